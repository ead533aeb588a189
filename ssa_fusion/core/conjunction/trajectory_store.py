"""Trajectories kept between re-screenings: `TrajectoryStore` and its `StoreView`.

A live catalog is re-screened again and again over a window that slides with the clock
(`watch`). Most objects' estimates did not change since the last re-screening: flying them
again from their estimates over the whole window would repeat the same integration. The
store keeps every object's states at the nodes of one grid of epochs that does not move
(multiples of ``step_s``, Unix s): an object whose estimate changed is flown again from it;
one whose estimate did not is only carried on from the last node it reached, as far as the
window now asks. The numbers are those of `ephemeris.StateEphemeris` sampled on the same
grid (the same fixed-step DOP853 chain, `propagation.integrate_chain`, step by step), so a
re-screening finds what a fresh screening of the newest estimates would, however the
re-screenings fell.

Memory: ~48 B per object and node (a day at 300 s: ~14 kB an object, 420 MB for 30,000).
Units: epochs Unix s (UTC), states GCRF km, km/s, covariances km², km²/s, km²/s².
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.types import MotionModel
from ssa_fusion.core.conjunction.ephemeris import carried_covariance, index_and_epochs
from ssa_fusion.core.earth.frames import pole_frame
from ssa_fusion.core.motion.propagation import integrate_chain

__all__ = ["StoreView", "TrajectoryStore"]

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]

NOT_FLOWN = np.iinfo(np.int64).min
"""An object's last node while it has not been flown since its estimate."""


class TrajectoryStore:
    """Every object's states at the nodes ``k step_s`` (module docstring).

    Objects are rows 0, 1, ... (the caller's indices); `set_estimates` gives a row its
    estimate (and forgets its trajectory), `ensure` flies rows to a range of nodes,
    `view` makes the `ephemeris.Ephemeris` a screening reads.
    """

    def __init__(self, model: MotionModel, step_s: float, max_step_s: float = 60.0,
                 covariance_step_s: float = 60.0) -> None:
        """Keep trajectories of ``model`` at nodes every ``step_s`` s.

        DOP853 steps of at most ``max_step_s`` s for the states, ``covariance_step_s`` s for
        the state transition matrices (`StoreView.covariance`).
        """
        if not (math.isfinite(step_s) and step_s > 0):
            raise ValueError(f"step_s must be a positive number, not {step_s!r}")
        self.model = MotionModel(model)
        self.step_s = float(step_s)
        self.max_step_s = float(max_step_s)
        self.covariance_step_s = float(covariance_step_s)
        self.x0 = np.zeros((0, 6))
        self.t0 = np.zeros(0)
        self.pole = np.zeros((0, 3, 3))
        self._last_k = np.zeros(0, dtype=np.int64)  # node each row reached, or NOT_FLOWN
        self._last_x = np.zeros((0, 6))  # its state there
        self._k0 = 0  # node of column 0 of _nodes
        self._nodes = np.zeros((0, 0, 6))  # (rows, columns, 6); NaN where not flown

    @property
    def rows(self) -> int:
        """Number of rows there is room for."""
        return int(self.t0.size)

    def node(self, t: ArrayLike) -> IntArray:
        """Return the node indices of epochs ``t`` (Unix s), which must lie on the grid."""
        k = np.rint(np.asarray(t, dtype=float) / self.step_s).astype(np.int64)
        return k

    def _grow_rows(self, n: int) -> None:
        """Make room for rows up to ``n`` (a quarter more, for the next ones)."""
        old = self.rows
        if n <= old:
            return
        add = max(n, old + old // 4) - old
        self.x0 = np.concatenate([self.x0, np.full((add, 6), np.nan)])
        self.t0 = np.concatenate([self.t0, np.full(add, np.nan)])
        self.pole = np.concatenate([self.pole, np.broadcast_to(np.eye(3), (add, 3, 3))])
        self._last_k = np.concatenate([self._last_k, np.full(add, NOT_FLOWN)])
        self._last_x = np.concatenate([self._last_x, np.full((add, 6), np.nan)])
        self._nodes = np.concatenate(
            [self._nodes, np.full((add, *self._nodes.shape[1:]), np.nan)])

    def set_estimates(self, rows: ArrayLike, x0: ArrayLike, t0: ArrayLike) -> None:
        """Give ``rows`` their estimates: states ``x0`` (M, 6) at epochs ``t0`` (M,).

        Their trajectories are forgotten (flown again from the estimates when asked).
        """
        r = np.asarray(rows, dtype=np.int64).ravel()
        if not r.size:
            return
        self._grow_rows(int(r.max()) + 1)
        self.x0[r] = np.asarray(x0, dtype=float).reshape(r.size, 6)
        self.t0[r] = np.asarray(t0, dtype=float).ravel()
        self.pole[r] = pole_frame(self.t0[r])
        self._last_k[r] = NOT_FLOWN
        self._nodes[r] = np.nan

    def keep_from(self, k: int) -> None:
        """Forget the nodes before node ``k`` (a window that slid past them)."""
        drop = min(k - self._k0, self._nodes.shape[1])
        if drop > 0:
            self._nodes = np.ascontiguousarray(self._nodes[:, drop:])
            self._k0 += drop
        elif not self._nodes.shape[1]:
            self._k0 = k

    def _grow_columns(self, k_from: int, k_to: int) -> None:
        """Make room for the nodes ``k_from`` to ``k_to`` (a quarter more after, for the next)."""
        have = self._nodes.shape[1]
        if not have:
            self._k0 = k_from
        before = max(self._k0 - k_from, 0)
        need = max(k_to - self._k0 + 1, have) + before
        if need > have + before or before:
            cols = max(need, have + have // 4 + before)
            grown = np.full((self.rows, cols, 6), np.nan)
            grown[:, before:before + have] = self._nodes
            self._nodes = grown
            self._k0 -= before

    def ensure(self, rows: IntArray, k_from: int, k_to: int) -> None:
        """Fly ``rows`` so that each holds its states at nodes ``k_from`` to ``k_to``.

        A row not flown since its estimate starts from it (its first step to node
        ``k_from``, backwards if the estimate is later); a row flown before is carried on
        from the last node it reached. States are NaN after a failed step.
        """
        self._grow_columns(k_from, k_to)
        last = self._last_k[rows]
        fresh = rows[last == NOT_FLOWN]
        if fresh.size:
            steps = np.full((fresh.size, k_to - k_from + 1), self.step_s)
            steps[:, 0] = k_from * self.step_s - self.t0[fresh]
            self._fly(fresh, self.x0[fresh], steps, np.full(fresh.size, k_from))
        behind = rows[(last != NOT_FLOWN) & (last < k_to)]
        if behind.size:
            count = k_to - self._last_k[behind]
            steps = np.where(np.arange(int(count.max()))[None, :] < count[:, None],
                             self.step_s, 0.0)
            self._fly(behind, self._last_x[behind], steps, self._last_k[behind] + 1)

    def _fly(self, rows: IntArray, x: Array, steps: Array, k_first: IntArray) -> None:
        """Integrate ``rows`` from ``x`` along ``steps`` (M, K); step j ends at node k_first + j.

        A zero step (the padding of shorter chains) ends nowhere: its state is not stored.
        """
        out, ok = integrate_chain(self.model, x, steps, self.max_step_s, self.pole[rows])
        out[~ok] = np.nan
        nodes = k_first[:, None] + np.arange(steps.shape[1])[None, :]
        real = np.ones(steps.shape, dtype=np.bool_)
        real[:, 1:] = steps[:, 1:] != 0.0
        ends = np.where(real, nodes, np.iinfo(np.int64).min).max(axis=1)
        self._last_k[rows] = ends
        self._last_x[rows] = out[np.arange(rows.size), ends - k_first]
        col = nodes - self._k0
        put = real & (col >= 0)
        self._nodes[np.broadcast_to(rows[:, None], steps.shape)[put], col[put]] = out[put]

    def states(self, rows: IntArray, k_from: int, k_to: int) -> Array:
        """Return the states (M, K, 6) of ``rows`` at nodes ``k_from`` to ``k_to`` (flying them)."""
        self.ensure(rows, k_from, k_to)
        a = k_from - self._k0
        return self._nodes[rows, a:a + k_to - k_from + 1]

    def exact(self, rows: IntArray, t: Array) -> Array:
        """States (M, 6) of ``rows`` at epochs ``t``: from the nearest node held, else estimate."""
        col = self.node(t) - self._k0
        inside = (col >= 0) & (col < self._nodes.shape[1])
        x, ts = self.x0[rows].copy(), self.t0[rows].copy()
        held = np.full((rows.size, 6), np.nan)
        held[inside] = self._nodes[rows[inside], col[inside]]
        use = np.isfinite(held).all(axis=1) & (
            np.abs(t - (col + self._k0) * self.step_s) < np.abs(t - ts))
        x[use], ts[use] = held[use], (col[use] + self._k0) * self.step_s
        x1, ok = integrate_chain(self.model, x, (t - ts)[:, None], self.max_step_s,
                                 self.pole[rows])
        out = x1[:, 0]
        out[~ok] = np.nan
        return out

    def view(self, rows: ArrayLike, covariance: ArrayLike | None = None) -> StoreView:
        """Return the `ephemeris.Ephemeris` of ``rows`` (ids: their row numbers as text).

        ``covariance`` (M, 6, 6): the rows' estimates' covariances (`StoreView.covariance`).
        """
        return StoreView(self, np.asarray(rows, dtype=np.int64).ravel(), covariance)


class StoreView:
    """Some rows of a `TrajectoryStore` as an `ephemeris.Ephemeris` (index i = ``rows[i]``).

    `sample` takes epochs on the store's grid only; ``object_ids`` are the row numbers.
    """

    def __init__(self, store: TrajectoryStore, rows: IntArray,
                 covariance: ArrayLike | None = None) -> None:
        """View ``rows`` of ``store``; ``covariance`` (M, 6, 6) their estimates' (optional)."""
        self.store = store
        self.rows = rows
        self.p0 = (None if covariance is None else
                   np.asarray(covariance, dtype=float).reshape(rows.size, 6, 6))
        self._ids = tuple(str(r) for r in rows)

    @property
    def object_ids(self) -> tuple[str, ...]:
        """The rows, as text, in index order."""
        return self._ids

    @property
    def local_exact(self) -> bool:
        """True: `exact` starts from the nearest node held."""
        return True

    def sample(self, t: ArrayLike) -> Array:
        """States (M, T, 6) at epochs ``t`` (consecutive nodes of the grid), GCRF km, km/s."""
        k = self.store.node(np.atleast_1d(np.asarray(t, dtype=float)))
        if k.size and not np.array_equal(k, np.arange(k[0], k[0] + k.size)):
            raise ValueError("a store is sampled at consecutive nodes of its grid only")
        if not k.size:
            return np.zeros((self.rows.size, 0, 6))
        return self.store.states(self.rows, int(k[0]), int(k[-1]))

    def exact(self, index: ArrayLike, t: ArrayLike) -> Array:
        """States (M, 6) of objects ``index`` at Unix epochs ``t``, GCRF km, km/s."""
        idx, tt = index_and_epochs(index, t)
        return self.store.exact(self.rows[idx], tt)

    def covariance(self, index: ArrayLike, t: ArrayLike) -> Array:
        """Covariances (M, 6, 6) of objects ``index`` carried to epochs ``t`` by the STM."""
        s, r = self.store, self.rows
        return carried_covariance(s.model, s.x0[r], s.t0[r], self.p0, s.pole[r], index, t,
                                  s.covariance_step_s)
