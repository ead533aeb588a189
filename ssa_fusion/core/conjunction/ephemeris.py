"""Where screened trajectories come from: `Ephemeris`, `ElementSetEphemeris`, `StateEphemeris`.

A screening (`screening.screen`) samples every object of a catalog on a coarse grid of
epochs (`Ephemeris.sample`) and, for the few close approaches it finds, asks for states at
arbitrary epochs (`Ephemeris.exact`): the time of closest approach and the miss distance
are those of the object's own propagation, never of an interpolant.

* `ElementSetEphemeris`: element sets propagated by SGP4/SDP4 (`element_sets.catalog_states`),
  turned from TEME to the GCRF;
* `StateEphemeris`: state estimates (a filter's, each at its own epoch) propagated by a
  `propagation.INTEGRATED_MODELS` model ("two_body", "j2", "drag"), with the covariances
  carried to any epoch by the state transition matrix (`StateEphemeris.covariance`).

Units: epochs Unix s (UTC), states GCRF km and km/s, covariances km², km²/s, km²/s².
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.types import MotionModel
from ssa_fusion.core.earth.frames import pole_frame, teme_to_gcrs_matrix
from ssa_fusion.core.earth.timescales import jd_utc
from ssa_fusion.core.motion.element_sets import CatalogEntry, catalog_states
from ssa_fusion.core.motion.propagation import integrate_chain, integrate_stm

__all__ = ["Covariances", "ElementSetEphemeris", "Ephemeris", "StateEphemeris",
           "carried_covariance", "index_and_epochs", "stm_chain"]

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

ROTATION_STEP_S = 10.0
"""`ElementSetEphemeris.exact` takes the TEME -> GCRF rotation at epochs rounded to this, s."""


class Ephemeris(Protocol):
    """Trajectories of a catalog, sampled at common epochs or evaluated one by one.

    ``object_ids`` names the objects (axis 0 of `sample`, the indices of `exact`).
    """

    @property
    def object_ids(self) -> tuple[str, ...]:
        """The objects' ids, in index order."""
        ...

    @property
    def local_exact(self) -> bool:
        """Whether `exact` is cheap only near the epochs of the last `sample`.

        A screening then asks for its states chunk by chunk, else once at the end.
        """
        ...

    def sample(self, t: ArrayLike) -> Array:
        """Return every object's GCRF state (N, T, 6), km and km/s, at Unix epochs ``t`` (T,).

        NaN where the object has no state (an element set SGP4 cannot propagate there).
        """
        ...

    def exact(self, index: ArrayLike, t: ArrayLike) -> Array:
        """Return the GCRF states (M, 6) of objects ``index`` (M,) at Unix epochs ``t`` (M,)."""
        ...


@runtime_checkable
class Covariances(Protocol):
    """An `Ephemeris` whose trajectories start from estimates with covariances.

    ``p0`` is None when it holds none.
    """

    p0: Array | None

    def covariance(self, index: ArrayLike, t: ArrayLike) -> Array:
        """Covariances (M, 6, 6) of objects ``index`` at Unix epochs ``t``, GCRF."""
        ...


class ElementSetEphemeris:
    """SGP4/SDP4 trajectories of element sets (`element_sets.CatalogEntry`), in the GCRF.

    `sample` propagates all of them at once (`catalog_states`, `sgp4.api.SatrecArray`);
    `exact` propagates each object of ``index`` at its own epochs (one vectorised SGP4 call
    per distinct object, not per pair).
    """

    def __init__(self, entries: Sequence[CatalogEntry]) -> None:
        """Hold the element sets ``entries`` (their order is the index order)."""
        self.entries = tuple(entries)
        self._ids = tuple(e.object_id for e in self.entries)

    @property
    def object_ids(self) -> tuple[str, ...]:
        """The objects' NORAD ids, in index order."""
        return self._ids

    @property
    def local_exact(self) -> bool:
        """False: SGP4 is as cheap at any epoch."""
        return False

    def sample(self, t: ArrayLike) -> Array:
        """SGP4 states (N, T, 6) at Unix epochs ``t``, GCRF km, km/s; NaN where SGP4 fails."""
        return catalog_states(self.entries, np.asarray(t, dtype=float)).x

    def exact(self, index: ArrayLike, t: ArrayLike) -> Array:
        """SGP4 states (M, 6) of objects ``index`` at epochs ``t``, GCRF km, km/s.

        NaN where SGP4 reports an error. TEME is turned to the GCRF by the rotation at the
        nearest multiple of `ROTATION_STEP_S` (it turns by < 1e-10 rad in that time: < 1 mm
        at GEO), the same for every object at one epoch.
        """
        idx, tt = index_and_epochs(index, t)
        out = np.full((idx.size, 6), np.nan)
        if not idx.size:
            return out
        order = np.argsort(idx, kind="stable")
        cuts = np.flatnonzero(np.diff(idx[order])) + 1
        for rows in np.split(order, cuts):
            jd, fr = jd_utc(tt[rows])
            err, r, v = self.entries[int(idx[rows[0]])].satrec.sgp4_array(jd, fr)
            teme = np.concatenate([r, v], axis=1)
            teme[err != 0] = np.nan
            out[rows] = teme
        good = np.flatnonzero(np.isfinite(out).all(axis=1))
        step = ROTATION_STEP_S
        node, where = np.unique(np.round(tt[good] / step), return_inverse=True)
        m = teme_to_gcrs_matrix(node * step)
        for a in range(0, good.size, 1 << 18):  # the rotations of 2^18 rows at a time
            rows, mm = good[a:a + (1 << 18)], m[where[a:a + (1 << 18)]]
            out[rows] = np.concatenate([np.einsum("nij,nj->ni", mm, out[rows, :3]),
                                        np.einsum("nij,nj->ni", mm, out[rows, 3:])], axis=1)
        return out


class StateEphemeris:
    """State estimates (each at its own epoch) propagated by an integrated motion model.

    Object i starts at ``x0[i]`` (GCRF km, km/s) at Unix epoch ``t0[i]`` and follows
    ``model`` (`propagation.INTEGRATED_MODELS`: "two_body", "j2", "drag"; J2 about the
    Earth's pole at each object's epoch, `frames.pole_frame`) with fixed DOP853 steps of at
    most ``max_step_s``. `sample` continues every object from the last epochs it sampled
    (a screening asks for its chunks in time order: each step is integrated once); `exact`
    integrates from the nearest sampled epoch of the last `sample` (at most half its spacing
    away) or, outside it, from the estimate's epoch.
    """

    def __init__(self, object_ids: Sequence[str], x0: ArrayLike, t0: ArrayLike,
                 model: MotionModel | str = MotionModel.J2, max_step_s: float = 60.0,
                 covariance: ArrayLike | None = None) -> None:
        """Hold the estimates: ids (N,), states ``x0`` (N, 6), epochs ``t0`` (N,) Unix s.

        ``covariance`` (N, 6, 6), km², km²/s, km²/s², optional (`covariance`).
        """
        self._ids = tuple(object_ids)
        self.x0 = np.array(x0, dtype=float).reshape(len(self._ids), 6)
        self.t0 = np.broadcast_to(np.asarray(t0, dtype=float), (len(self._ids),)).copy()
        self.model = MotionModel(model)
        self.max_step_s = float(max_step_s)
        self.p0 = (None if covariance is None else
                   np.array(covariance, dtype=float).reshape(len(self._ids), 6, 6))
        self._pole = pole_frame(self.t0) if len(self._ids) else np.zeros((0, 3, 3))
        self._cursor_t = self.t0.copy()
        self._cursor_x = self.x0.copy()
        self._last_t = np.zeros(0)
        self._last_x = np.zeros((len(self._ids), 0, 6))

    @property
    def object_ids(self) -> tuple[str, ...]:
        """The objects' ids, in index order."""
        return self._ids

    @property
    def local_exact(self) -> bool:
        """True: `exact` integrates from the last sampled epochs when they are nearer."""
        return True

    def sample(self, t: ArrayLike) -> Array:
        """Propagated states (N, T, 6) at Unix epochs ``t`` (increasing), GCRF km, km/s.

        NaN where the propagation failed (a non-finite state).
        """
        tt = np.atleast_1d(np.asarray(t, dtype=float))
        n = len(self._ids)
        if not n or not tt.size:
            return np.zeros((n, tt.size, 6))
        fresh = self._cursor_t > tt[0]  # asked again for earlier epochs: from the estimate
        self._cursor_t[fresh] = self.t0[fresh]
        self._cursor_x[fresh] = self.x0[fresh]
        steps = np.diff(np.concatenate([self._cursor_t[:, None],
                                        np.broadcast_to(tt, (n, tt.size))], axis=1), axis=1)
        x, ok = integrate_chain(self.model, self._cursor_x, steps, self.max_step_s, self._pole)
        x[~ok] = np.nan
        self._cursor_t[:] = tt[-1]
        self._cursor_x = x[:, -1].copy()
        self._last_t, self._last_x = tt.copy(), x
        return x

    def _start(self, idx: IntArray, tt: Array) -> tuple[Array, Array]:
        """Return where objects ``idx`` start for epochs ``tt``: (states (M, 6), epochs (M,)).

        The nearer in time of the estimate and the nearest epoch of the last `sample`.
        """
        x, t = self.x0[idx].copy(), self.t0[idx].copy()
        lt = self._last_t
        if lt.size:
            hi = np.clip(np.searchsorted(lt, tt), 0, lt.size - 1)
            lo = np.maximum(hi - 1, 0)
            k = np.where(np.abs(tt - lt[lo]) <= np.abs(tt - lt[hi]), lo, hi)
            xs = self._last_x[idx, k]
            use = np.isfinite(xs).all(axis=1) & (np.abs(tt - lt[k]) < np.abs(tt - t))
            x[use], t[use] = xs[use], lt[k][use]
        return x, t

    def exact(self, index: ArrayLike, t: ArrayLike) -> Array:
        """Propagated states (M, 6) of objects ``index`` at Unix epochs ``t``, GCRF km, km/s."""
        idx, tt = index_and_epochs(index, t)
        if not idx.size:
            return np.zeros((0, 6))
        x, ts = self._start(idx, tt)
        x1, ok = integrate_chain(self.model, x, (tt - ts)[:, None], self.max_step_s,
                                 self._pole[idx])
        out = x1[:, 0]
        out[~ok] = np.nan
        return out

    def covariance(self, index: ArrayLike, t: ArrayLike) -> Array:
        """Covariances (M, 6, 6) of objects ``index`` carried to epochs ``t`` by the STM.

        ``Phi P0 Phi^T`` with Phi from each estimate's epoch (GCRF km², km²/s, km²/s²); NaN
        when the ephemeris holds no covariance. Each object is integrated once along its
        own epochs in time order (`stm_chain`), however many of them it has: the cost is
        its span, not the sum of the spans from its estimate.
        """
        return carried_covariance(self.model, self.x0, self.t0, self.p0, self._pole, index, t,
                                  self.max_step_s)


def index_and_epochs(index: ArrayLike, t: ArrayLike) -> tuple[IntArray, Array]:
    """Return ``index`` as int64 (M,) and ``t`` (Unix s) broadcast to it, a copy (M,)."""
    idx = np.asarray(index, dtype=np.int64).ravel()
    return idx, np.broadcast_to(np.asarray(t, dtype=float).ravel(), idx.shape).copy()


def carried_covariance(model: MotionModel, x0: Array, t0: Array, p0: Array | None,
                       pole: Array, index: ArrayLike, t: ArrayLike, max_step_s: float
                       ) -> Array:
    """Covariances (M, 6, 6) of objects ``index`` carried from their estimates to ``t``.

    ``Phi P0 Phi^T`` with Phi of `stm_chain` (estimates ``x0`` (N, 6), ``t0`` (N,),
    ``p0`` (N, 6, 6) GCRF; ``pole`` (N, 3, 3)); NaN where the propagation failed, and
    everywhere when ``p0`` is None.
    """
    idx, tt = index_and_epochs(index, t)
    if p0 is None:
        return np.full((idx.size, 6, 6), np.nan)
    phi, ok = stm_chain(model, x0, t0, idx, tt, max_step_s, pole)
    p: Array = phi @ p0[idx] @ np.swapaxes(phi, 1, 2)
    p[~ok] = np.nan
    return p


def stm_chain(model: MotionModel, x0: Array, t0: Array, index: IntArray, t: Array,
              max_step_s: float, pole: Array) -> tuple[Array, BoolArray]:
    """State transition matrices (M, 6, 6) of objects ``index`` from ``t0[index]`` to ``t``.

    Each object's rows are taken in time order: the k-th from the (k-1)-th's state, and its
    matrix the product of the steps' (`propagation.integrate_stm`, one vectorised call per
    rank k across the objects). States ``x0`` (N, 6) GCRF km, km/s at Unix epochs ``t0``
    (N,); ``pole`` (N, 3, 3) each object's `frames.pole_frame`. Returns (Phi, ok (M,)):
    ok False where the propagation failed on the way.
    """
    m = index.size
    phi_out = np.zeros((m, 6, 6))
    ok_out = np.zeros(m, dtype=np.bool_)
    if not m:
        return phi_out, ok_out
    order = np.lexsort((t, index))
    obj = index[order]
    starts = np.flatnonzero(np.r_[True, obj[1:] != obj[:-1]])
    group = np.cumsum(np.r_[True, obj[1:] != obj[:-1]]) - 1
    rank = np.arange(m) - starts[group]
    owner = obj[starts]
    x, t_at = x0[owner].copy(), t0[owner].copy()
    phi = np.broadcast_to(np.eye(6), (owner.size, 6, 6)).copy()
    ok = np.ones(owner.size, dtype=np.bool_)
    by_rank = np.argsort(rank, kind="stable")
    cuts = np.flatnonzero(np.diff(rank[by_rank])) + 1
    for rows in np.split(by_rank, cuts):  # rows of one rank: one per object, at most
        g, at = group[rows], t[order[rows]]
        x1, step, good = integrate_stm(model, x[g], at - t_at[g], max_step_s, pole[owner[g]])
        phi[g] = step @ phi[g]
        x[g], t_at[g], ok[g] = x1, at, ok[g] & good
        phi_out[order[rows]], ok_out[order[rows]] = phi[g], ok[g]
    return phi_out, ok_out
