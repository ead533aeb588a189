"""Initial orbit determination of one object: the batch of real measurements that starts its EKF.

`OrbitInitiator.add(m, samples, p0_sigma)` takes the measurements a `tracker.Tracker` admitted
before its filter exists, in arrival order, and returns either why it did not start the filter
or the initial state. The two settings come with each call (the tracker's current
``config.iod_samples`` and ``config.p0_sigma``, which may change at run time: a change applies
to the batch being collected). The rules during IOD:

* a forecast is ignored (`Cause.IGNORED_BEFORE_IOD`): IOD uses real measurements only;
* a real measurement older than the last one collected is stale, one at its epoch from
  the same station a duplicate (`Cause.REJECTED_STALE`, `Cause.REJECTED_DUPLICATE`), one
  at its epoch from another station is not used by the batch (`Cause.IGNORED_BEFORE_IOD`);
* a batch comes from one station, of one kind, within ``max_span_s`` of its first
  measurement (one pass): a measurement from another station, of another kind, or later
  than that starts a new batch;
* until ``max(2, samples)`` are collected the answer is `Cause.IOD_PENDING`; then the batch is
  solved (`OrbitInitiator.solve`) and emptied: range/az/el by Herrick-Gibbs at the middle of
  the first, middle and last sample, ra/dec by Gauss's angles-only method (with iterative
  improvement) at the same three, positions by finite differences at the last epoch
  (`iod`), the covariance being the measurement noise pushed through that map (numerical
  Jacobian). A non-finite solution is `Cause.IOD_FAILED`;
* the filter starts at the batch's last epoch, with the covariance floor ``p0_sigma`` added
  (in quadrature) and, for Herrick-Gibbs, the state and covariance predicted there by the
  placeholder dynamics.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import cast

import numpy as np

from ssa_fusion.core.base.constants import MU_EARTH, R_EARTH
from ssa_fusion.core.base.types import Cause, Measurement, Source
from ssa_fusion.core.earth.frames import enu_matrix
from ssa_fusion.core.measure import iod
from ssa_fusion.core.measure.measurement import (
    MeasurementModel,
    PositionModel,
    RadecModel,
    RazelModel,
    StationModels,
)

Rotations = Callable[[np.ndarray], np.ndarray]
"""ITRS -> GCRS rotations (k, 3, 3) at Unix (UTC) epochs (k,): `iod.itrs_to_gcrs_at`, or a
caller's look-up of the same matrices computed beforehand (equal bit for bit)."""

Placeholder = Callable[[np.ndarray, float, float], tuple[np.ndarray, np.ndarray]]
"""Placeholder dynamics ``f(x, dt, t0) -> (x_new, F)``: the state ``dt`` s after its epoch
``t0`` (s on the measurements' clock, Unix s for orbits) and its Jacobian."""


def earth_orbit_problem(x: np.ndarray) -> str:
    """Why GCRF state `x` (km, km/s) is no Earth orbit a ground station tracks, or "".

    It must lie above the Earth's surface and be bound (specific energy v^2/2 - mu/r < 0):
    a batch with an outlier (a range of 1e6 km among ranges of 1e3) gives neither.
    """
    r = float(np.linalg.norm(x[:3]))
    energy = 0.5 * float(np.dot(x[3:6], x[3:6])) - MU_EARTH / r if r > 0 else math.inf
    if r < R_EARTH:
        return f"|r| = {r:.1f} km is inside the Earth"
    if energy >= 0.0:
        return f"not a bound orbit: |r| = {r:.4g} km, energy {energy:.4g} km^2/s^2 >= 0"
    return ""


@dataclass
class InitialState:
    """The state an IOD batch starts the filter with.

    Attributes
    ----------
    t : float
        Epoch, s: the batch's last measurement.
    x : ndarray, shape (n,)
        State at `t`.
    P : ndarray, shape (n, n)
        Its covariance (symmetric): the IOD covariance plus the floor, predicted to `t`.
    """

    t: float
    x: np.ndarray
    P: np.ndarray


class OrbitInitiator:
    """Collects real measurements until an IOD batch is complete and solves it.

    Parameters
    ----------
    f : Placeholder
        Placeholder dynamics, used to move a Herrick-Gibbs state to the batch's last epoch.
    model : MeasurementModel
        Measurement model of the batch (the measurements' kind chooses the IOD method); for
        a station network, the batch's station's model.
    n : int
        State size (``[position, velocity]``, n/2 each).
    to_gcrs : Rotations
        The Earth's orientation at a range/az/el batch's epochs (`Rotations`).

    Attributes
    ----------
    batch : list of Measurement
        The real measurements collected so far, in increasing epoch order.
    """

    def __init__(self, f: Placeholder, model: MeasurementModel, n: int,
                 to_gcrs: Rotations = iod.itrs_to_gcrs_at) -> None:
        self.f = f
        self.to_gcrs = to_gcrs
        self.model = model
        self.n = n
        self.batch: list[Measurement] = []

    def add(self, m: Measurement, samples: int, p0_sigma: tuple[float, ...],
            max_span_s: float = math.inf) -> InitialState | tuple[str, str]:
        """Collect `m` (an admitted measurement); solve the batch once it is complete.

        Parameters
        ----------
        m : Measurement
            The next measurement, already validated.
        samples : int
            Real measurements per batch (at least 2 are used).
        p0_sigma : tuple of float, (n,)
            Standard deviations added in quadrature to the IOD covariance, state units.
        max_span_s : float
            Longest span of one batch, s (see the module docstring).

        Returns
        -------
        InitialState or tuple of str
            The initial state when `m` completed the batch and it was solved; otherwise
            ``(cause, detail)``: a `Cause` key and a sentence for the log.
        """
        got = self.collect(m, samples, max_span_s)
        if isinstance(got, tuple):
            return got
        return self.finish(got, p0_sigma)

    def collect(self, m: Measurement, samples: int,
                max_span_s: float = math.inf) -> list[Measurement] | tuple[str, str]:
        """Collect `m` (`add`'s first half); return the batch once complete (emptied).

        Else ``(cause, detail)`` as `add` gives it. The batch is then `finish`'s (or, for
        many objects at once, `finish_razel`'s).
        """
        if m.source == Source.FORECAST:
            return Cause.IGNORED_BEFORE_IOD, "forecast before IOD"
        if self.batch and m.t < self.batch[-1].t:
            return Cause.REJECTED_STALE, f"t={m.t} during IOD"
        if self.batch and m.t == self.batch[-1].t:
            if m.frame_id == self.batch[-1].frame_id:
                return Cause.REJECTED_DUPLICATE, f"t={m.t} during IOD"
            return (Cause.IGNORED_BEFORE_IOD,
                    f"t={m.t} from {m.frame_id!r}: the IOD batch is {self.batch[-1].frame_id!r}'s")
        if self.batch and (m.frame_id != self.batch[0].frame_id or m.kind != self.batch[0].kind
                           or m.t - self.batch[0].t > max_span_s):
            self.batch = []  # a new pass, station or kind: start again from m
        self.batch.append(m)
        if len(self.batch) < max(2, samples):
            return Cause.IOD_PENDING, "collecting IOD measurements"
        batch, self.batch = self.batch, []
        return batch

    def finish(self, batch: list[Measurement],
               p0_sigma: tuple[float, ...]) -> InitialState | tuple[str, str]:
        """Solve a complete `batch` (`collect`'s) into a state (`add`'s second half)."""
        t_last = batch[-1].t
        try:
            with np.errstate(over="raise", invalid="raise", divide="raise"):
                t_init, x0, P_iod = self.solve(batch)
                P0 = P_iod + np.diag(np.asarray(p0_sigma, dtype=float) ** 2)
                if t_last != t_init:  # Herrick-Gibbs solves at the middle epoch: move on
                    x0, F = self.f(x0, t_last - t_init, t_init)
                    P0 = F @ P0 @ F.T
        except (ValueError, OverflowError, FloatingPointError, ZeroDivisionError,
                np.linalg.LinAlgError) as exc:  # geometry no orbit fits (never raised on)
            return (Cause.IOD_FAILED,
                    f"initial orbit determination failed ({type(exc).__name__}: {exc})")
        if not (np.isfinite(x0).all() and np.isfinite(P0).all()):
            return Cause.IOD_FAILED, "initial orbit determination failed (non-finite state)"
        if isinstance(self.model, StationModels | RazelModel | RadecModel):
            problem = earth_orbit_problem(x0)
            if problem:  # an outlier in the batch (say a range of 1e6 km): start again
                return Cause.IOD_FAILED, f"initial orbit determination failed ({problem})"
        return InitialState(t_last, x0, 0.5 * (P0 + P0.T))

    def solve(self, batch: list[Measurement]) -> tuple[float, np.ndarray, np.ndarray]:
        """Return (epoch, state, covariance) from an IOD batch.

        Parameters
        ----------
        batch : list of Measurement
            Real measurements in increasing epoch order (at least 2; 3 for range/az/el).

        Returns
        -------
        t : float
            Epoch of the solution: the middle sample (range/az/el) or the last (positions).
        x : ndarray, shape (n,)
            State at `t` (non-finite when the batch cannot be solved).
        P : ndarray, shape (n, n)
            The measurement noise pushed through the IOD map (numerical Jacobian, one
            evaluation per input channel with non-zero variance).
        """
        t = np.array([b.t for b in batch])
        Z = np.array([b.z for b in batch], dtype=float)
        model = (self.model.get(batch[0].kind, batch[0].frame_id)
                 if isinstance(self.model, StationModels) else self.model)
        solve_all: Callable[[np.ndarray], np.ndarray] | None = None  # of stacked batches
        if isinstance(model, RazelModel | RadecModel):
            mid = len(batch) // 2
            i3 = [0, mid, len(batch) - 1]
            t3 = t[i3]
            station = model

            if isinstance(model, RazelModel):
                to_gcrs = self.to_gcrs(station.unix0 + t3)  # once for every solve

                def solve_all(zs: np.ndarray) -> np.ndarray:
                    r = iod.razel_to_gcrs(zs[:, i3], station.unix0 + t3, station.station,
                                          to_gcrs)
                    v2 = iod.herrick_gibbs(r[:, 0], r[:, 1], r[:, 2], t3[0], t3[1], t3[2])
                    return np.concatenate([r[:, 1], v2], -1)
            else:
                sites = np.array([station.site_gcrs(ti) for ti in t3])

                def solve(zs: np.ndarray) -> np.ndarray:
                    r2, v2 = iod.gauss_angles_only(t3, zs[i3, 0], zs[i3, 1], sites)
                    return np.concatenate([r2, v2])

            t_init = float(t3[1])
            used = i3  # the other samples do not enter the solution: their Jacobian is 0
        else:
            observed = list(cast(PositionModel, model).observed)

            def solve(zs: np.ndarray) -> np.ndarray:
                x = np.zeros(self.n)
                fd = iod.finite_difference_state(t, zs)
                k = len(observed)
                x[observed] = fd[:k]
                x[[i + self.n // 2 for i in observed]] = fd[k:]
                return x

            t_init = float(t[-1])
            used = list(range(len(batch)))
        # the batch and each perturbation of it (one channel of one used sample by its
        # standard deviation) solved at once: x0, then the Jacobian's columns
        sigs = {j: np.sqrt(np.clip(np.diag(np.asarray(batch[j].R, dtype=float)), 0.0, None))
                for j in dict.fromkeys(used)}  # in order, once each (a batch of 2: i3 repeats)
        cols = [(j, c) for j, sig in sigs.items() for c in range(Z.shape[1]) if sig[c] != 0.0]
        Zs = np.repeat(Z[None], 1 + len(cols), axis=0)
        for q, (j, c) in enumerate(cols, 1):
            Zs[q, j, c] += sigs[j][c]
        X = solve_all(Zs) if solve_all is not None else np.stack([solve(zs) for zs in Zs])
        x0 = X[0]
        P = np.zeros((self.n, self.n))
        for j, sig in sigs.items():
            if not sig.any():
                continue
            J = np.zeros((self.n, Z.shape[1]))
            for q, (jj, c) in enumerate(cols, 1):
                if jj == j:
                    J[:, c] = (X[q] - x0) / sig[c]
            P += J @ np.asarray(batch[j].R, dtype=float) @ J.T
        return t_init, x0, P


PlaceholderMany = Callable[[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]
"""`Placeholder` for K states at once: ``f(x (K, n), dt (K,), t0 (K,)) -> (x_new, F)``, each
state as `Placeholder` moves it alone (the same numbers)."""


def finish_razel(initiators: Sequence[OrbitInitiator], batches: Sequence[list[Measurement]],
                 p0_sigma: tuple[float, ...], f: PlaceholderMany,
                 to_gcrs: Rotations) -> list[InitialState | tuple[str, str]]:
    """`OrbitInitiator.finish` of K complete batches at once, vectorised over the batches.

    Range/az/el batches (their initiators' models: `RazelModel`, or `StationModels` naming
    one) are solved together: the Herrick-Gibbs solutions of every batch and of each of its
    perturbations (`OrbitInitiator.solve`), the covariances, and one call of `f` moving every
    state to its batch's last epoch; the same steps in the same order for each element, so
    the states and covariances are `finish`'s to rounding. A batch of another kind, or one
    whose numbers are not all finite, goes through its initiator's own `finish` (which
    names the cause, e.g. a FloatingPointError). `to_gcrs`: the initiators' Earth
    orientation. Returns one answer per batch, in order.
    """
    out: list[InitialState | tuple[str, str] | None] = [None] * len(batches)
    pick: list[int] = []
    models: list[RazelModel] = []
    for k, (init, batch) in enumerate(zip(initiators, batches, strict=True)):
        model = (init.model.get(batch[0].kind, batch[0].frame_id)
                 if isinstance(init.model, StationModels) else init.model)
        if isinstance(model, RazelModel) and init.n == 6 and len(batch) >= 3:
            pick.append(k)
            models.append(model)
    if pick:
        with np.errstate(all="ignore"):
            done = _solve_razel([batches[k] for k in pick], models, p0_sigma, f, to_gcrs)
        for k, state in zip(pick, done, strict=True):
            out[k] = state
    return [o if o is not None else init.finish(batch, p0_sigma)
            for o, init, batch in zip(out, initiators, batches, strict=True)]


def _solve_razel(batches: Sequence[list[Measurement]], models: Sequence[RazelModel],
                 p0_sigma: tuple[float, ...], f: PlaceholderMany,
                 to_gcrs: Rotations) -> list[InitialState | None]:
    """Solve K range/az/el batches at once (`finish_razel`'s vectorised part).

    None for a batch whose numbers are not all finite or whose state is no Earth orbit
    (`earth_orbit_problem`): `OrbitInitiator.finish` names why.
    """
    n_b = len(batches)
    i3 = np.array([[0, len(b) // 2, len(b) - 1] for b in batches])
    t3 = np.array([[b[j].t for j in row] for b, row in zip(batches, i3.tolist(), strict=True)])
    Z = np.array([[b[j].z for j in row] for b, row in zip(batches, i3.tolist(), strict=True)],
                 dtype=float)  # (K, 3 samples, 3 channels)
    R = np.array([[b[j].R for j in row] for b, row in zip(batches, i3.tolist(), strict=True)],
                 dtype=float)  # (K, 3, 3, 3)
    sig = np.sqrt(np.clip(np.diagonal(R, axis1=2, axis2=3), 0.0, None))  # (K, 3, 3)
    # the batch (q = 0) and each channel c of each sample j moved by its sigma (q = 1 + 3j + c)
    Zs = np.repeat(Z[:, None], 10, axis=1)
    q = 1 + np.arange(9)
    Zs[:, q, (q - 1) // 3, (q - 1) % 3] += sig.reshape(n_b, 9)
    unix0 = np.array([m.unix0 for m in models])
    rot = to_gcrs((unix0[:, None] + t3).reshape(-1)).reshape(n_b, 1, 3, 3, 3)
    rng, az, el = Zs[..., 0], Zs[..., 1], Zs[..., 2]
    ce = np.cos(el)
    enu = np.stack([rng * ce * np.sin(az), rng * ce * np.cos(az), rng * np.sin(el)], -1)
    to_itrs = np.array([enu_matrix(m.station.lat_rad, m.station.lon_rad) for m in models])
    site = np.array([m.station.itrs for m in models])
    r = np.einsum("...ij,...j->...i", rot,
                  enu @ to_itrs[:, None] + site[:, None, None])  # (K, 10, 3, 3)
    t1, t2, t3_ = (t3[:, j, None, None] for j in range(3))
    v2 = iod.herrick_gibbs(r[:, :, 0], r[:, :, 1], r[:, :, 2], t1, t2, t3_)
    X = np.concatenate([r[:, :, 1], v2], -1)  # (K, 10, 6)
    x0 = X[:, 0]
    used = sig != 0.0
    J = np.where(used.reshape(n_b, 1, 9),
                 (X[:, 1:] - x0[:, None]).transpose(0, 2, 1)
                 / np.where(used, sig, 1.0).reshape(n_b, 1, 9), 0.0).reshape(n_b, 6, 3, 3)
    P = np.zeros((n_b, 6, 6))
    for j in range(3):
        Jj = J[:, :, j]
        P += Jj @ R[:, j] @ np.swapaxes(Jj, 1, 2)
    P0 = P + np.diag(np.asarray(p0_sigma, dtype=float) ** 2)
    t_init = t3[:, 1]
    t_last = np.array([b[-1].t for b in batches])
    x1, F = f(x0, t_last - t_init, t_init)
    move = (t_last != t_init)[:, None, None]
    P1 = np.where(move, F @ P0 @ np.swapaxes(F, 1, 2), P0)
    x1 = np.where(move[:, :, 0], x1, x0)
    good = (np.isfinite(X).all(axis=(1, 2)) & np.isfinite(x1).all(axis=1)
            & np.isfinite(P1).all(axis=(1, 2)))
    return [InitialState(float(tl), x, 0.5 * (p + p.T))
            if ok and not earth_orbit_problem(x) else None
            for tl, x, p, ok in zip(t_last.tolist(), x1, P1, good.tolist(), strict=True)]
