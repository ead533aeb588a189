"""Initial orbit determination and EKF for a catalog of objects, batched: `TrackBank`.

A `TrackBank` keeps one track per ``object_id`` in arrays (state (N, 6) km, km/s GCRF,
covariance (N, 6, 6), epoch (N,) Unix s). `TrackBank.process` takes a batch of range/
azimuth/elevation measurements of any objects, in epoch order, and applies the per-object
`tracker.Tracker` rules to each object, vectorised over objects, with the per-object
tracker's options (`filter_options.FilterOptions`):

* an object without a track collects its first measurements in its own
  `initiation.OrbitInitiator` (Herrick-Gibbs over one pass of one station, ``iod_samples``
  measurements within ``iod_max_span_s``) until the batch is solved and its track starts
  (the batches completed in one round solved together: `initiation.finish_razel`);
* an object with a track predicts to each measurement and fuses it (`batch_ekf.BatchEKF`:
  one call per *round*, a round holding at most one measurement per object: the k-th
  measurement of every object in the batch goes in round k);
* a measurement older than the object's last fused one is stale; one at the same epoch
  from a station that has not yet measured the object at that epoch is fused (networks
  see an object from two sites at once: both are information), one from the same
  station again a duplicate (the per-object tracker's rules); a rejected update leaves
  the track as it was;
* after ``reinit_after`` measurements in a row beyond the gate the track is dropped and
  its IOD starts again from the last of them (`Cause.REINITIALISED`).

Plausibility (`validation.measurement_problem`) is the caller's: the node checks each
message as it arrives. Not done here (the per-object tracker's): forecasts and their
rollback, light time, kinds other than range/az/el.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from itertools import repeat

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.types import Cause, Kind, Measurement
from ssa_fusion.core.catalog.batch_ekf import REASONS, BatchEKF, Code
from ssa_fusion.core.earth import frames
from ssa_fusion.core.earth.frames import Station
from ssa_fusion.core.earth.timescales import DAY_S, UNIX_EPOCH_JD
from ssa_fusion.core.filter.initiation import InitialState, OrbitInitiator, finish_razel
from ssa_fusion.core.filter.options import FilterOptions
from ssa_fusion.core.measure.measurement import StationModels
from ssa_fusion.core.measure.validation import MAX_OBJECTS

Array = NDArray[np.float64]


@dataclass(frozen=True)
class BankResult:
    """What `TrackBank.process` did with a batch of M measurements (input order).

    Attributes
    ----------
    cause : list of str
        Per measurement: "" when fused (or when it started a track), else a `types.Cause`
        key (``iod_pending`` while an IOD batch is collected).
    fused : ndarray (K,) of int
        Indices of the measurements that produced an estimate (fused, or ended an IOD
        batch), in processing order.
    x, P : ndarray (K, 6), (K, 6, 6)
        The estimate each of them produced, at its epoch (km, km/s GCRF; km^2 ...).
    nis : ndarray (K,)
        Its normalized innovation squared (0 for a track started by IOD).
    """

    cause: list[str]
    fused: NDArray[np.int64]
    x: Array
    P: Array
    nis: Array


def station_bit(station: NDArray[np.int64]) -> NDArray[np.uint64]:
    """Return each station index's bit in `TrackBank.stations_at_t` (``1 << index % 64``)."""
    return np.left_shift(np.uint64(1), (station % 64).astype(np.uint64))


@dataclass
class _Batch:
    """One `TrackBank.process` call's measurements and what became of them (input order).

    ``rows`` (M,) each measurement's bank row (-1: the bank is full), ``station`` (M,) its
    station index (-1: out of every round), ``cause`` as `BankResult.cause`; the estimates
    produced so far in ``out_*`` (`emit`); ``rot`` the GCRF -> ITRF rotations of the
    batch's epochs, computed at its first round of updates.
    """

    t: Array
    z: Array
    R: Array
    object_ids: Sequence[str]
    frame_ids: Sequence[str]
    rows: NDArray[np.int64]
    station: NDArray[np.int64]
    cause: list[str]
    out_i: list[NDArray[np.int64]] = field(default_factory=list)
    out_x: list[Array] = field(default_factory=list)
    out_cov: list[Array] = field(default_factory=list)
    out_nis: list[Array] = field(default_factory=list)
    rot: tuple[Array, NDArray[np.intp]] | None = None

    def measurement(self, i: int) -> Measurement:
        """Return row `i` as a Measurement for an IOD batch.

        With its own z and R: the batch may keep it for hours, and views would keep the
        whole batch's arrays alive with it.
        """
        return Measurement(float(self.t[i]), self.z[i].copy(), self.R[i].copy(),
                           kind=Kind.RANGE_AZ_EL, object_id=self.object_ids[i],
                           frame_id=self.frame_ids[i])

    def emit(self, idx: NDArray[np.int64], x: Array, P: Array, nis: Array) -> None:
        """Record the estimates the measurements ``idx`` produced."""
        self.out_i.append(idx)
        self.out_x.append(x)
        self.out_cov.append(P)
        self.out_nis.append(nis)

    def result(self) -> BankResult:
        """Return what the batch did (`BankResult`)."""
        if self.out_i:
            return BankResult(self.cause, np.concatenate(self.out_i), np.concatenate(self.out_x),
                              np.concatenate(self.out_cov), np.concatenate(self.out_nis))
        return BankResult(self.cause, np.zeros(0, np.int64), np.zeros((0, 6)),
                          np.zeros((0, 6, 6)), np.zeros(0))


def _rounds(rows: NDArray[np.int64], station: NDArray[np.int64]) -> list[NDArray[np.int64]]:
    """Split a batch into rounds: the k-th measurement of each object goes in round k.

    Each round's measurements in batch order, the empty rounds left out; only the
    measurements with a station (``station >= 0``) take part.
    """
    m = rows.size
    order = np.argsort(rows, kind="stable")  # by row, then in batch order
    first = np.r_[True, rows[order][1:] != rows[order][:-1]]
    start = np.maximum.accumulate(np.where(first, np.arange(m), 0))
    rank = np.empty(m, dtype=np.int64)
    rank[order] = np.arange(m) - start
    live = np.flatnonzero(station >= 0)
    by_round = live[np.argsort(rank[live], kind="stable")]
    ends = np.searchsorted(rank[by_round], np.arange(int(rank.max(initial=-1)) + 2))
    rounds = (by_round[ends[k]:ends[k + 1]] for k in range(ends.size - 1))
    return [idx for idx in rounds if idx.size]


class TrackBank:
    """Tracks of many objects (module docstring).

    Parameters
    ----------
    config : FilterOptions
        Of every track: IOD (``iod``: 3 samples or more, Herrick-Gibbs; a P0 floor of 6
        values; ValueError otherwise), noise and motion model (`batch_ekf.BatchEKF`).
    stations : dict of str to frames.Station
        The network: the ``frame_id`` of a measurement names its station.
    capacity : int
        Initial number of rows (grows by doubling as objects arrive).
    max_objects : int
        The most objects it holds: a measurement of one more is refused
        (``rejected_bank_full``), so a flood of new object ids cannot take the machine's
        memory (~2 kB per object in a node), unless an object can be evicted.
    evict_after_s : float
        When the bank is full, the object measured longest ago is evicted (its row goes to
        the new object; `evicted` counts them) if its last measurement is more than this
        before the new one (s; inf: never). Objects measured since are never evicted, so a
        flood of new ids is refused rather than pushing out the catalog.
    jd0 : float
        UTC Julian date of t = 0 of the measurement clock (Unix time by default).
    """

    def __init__(self, config: FilterOptions, stations: dict[str, Station],
                 capacity: int = 64, jd0: float = UNIX_EPOCH_JD,
                 max_objects: int = MAX_OBJECTS, evict_after_s: float = math.inf) -> None:
        iod = config.iod
        if iod.iod_samples < 3:
            raise ValueError(f"iod_samples must be >= 3 (Herrick-Gibbs), got {iod.iod_samples}")
        if len(iod.p0_sigma) != 6:
            raise ValueError(f"p0_sigma needs 6 values, got {len(iod.p0_sigma)}")
        self.config = config
        self.ekf = BatchEKF(config, list(stations.values()), jd0)
        self.models = StationModels(stations, jd0)
        self.rows: dict[str, int] = {}
        self.object_ids: list[str] = []
        self.max_objects = int(max_objects)
        self.evict_after_s = float(evict_after_s)
        self.evicted = 0
        """Objects evicted to make room (`evict_after_s`)."""
        cap = max(1, int(capacity))
        self.x = np.zeros((cap, 6))
        self.P = np.zeros((cap, 6, 6))
        self.t = np.full(cap, -math.inf)
        """Epoch of each track's state (Unix s), -inf before its IOD."""
        self.tracking = np.zeros(cap, dtype=bool)
        self.gate_misses = np.zeros(cap, dtype=np.int64)
        """Measurements refused by the gate in a row, per object."""
        self.stations_at_t = np.zeros(cap, dtype=np.uint64)
        """The stations whose measurements were fused at each track's epoch `t`: bit
        ``index % 64`` of the network's station index (with more than 64 stations two may
        share a bit, and the second one's same-epoch measurement is counted a duplicate)."""
        self.seen = np.full(cap, -math.inf)
        """Epoch of the last measurement of each object (Unix s), fused or not."""
        self._initiators: dict[int, OrbitInitiator] = {}
        self._unix0 = (jd0 - UNIX_EPOCH_JD) * DAY_S
        """Unix time of t = 0 of the measurement clock (s), as the station models have it."""
        self._batch_t = np.zeros(0)
        """The epochs of the batch being processed (s on the measurement clock)."""
        self._iod_rotations: tuple[Array, Array] | None = None
        """Sorted Unix epochs (k,) of the batch and of the pending IOD batches and their
        GCRS -> ITRS rotations (k, 3, 3), computed at the batch's first IOD solve
        (`_iod_to_gcrs`); None until then and after the batch."""

    def _iod_to_gcrs(self, t_unix: np.ndarray) -> Array:
        """ITRS -> GCRS rotations at IOD epochs (Unix s), as `iod.itrs_to_gcrs_at` gives them.

        At the batch's first IOD solve, the rotations of every epoch of the batch and of
        the measurements pending in IOD batches are computed in one call (one per solve
        otherwise; each epoch's rotation is the same either way, bit for bit); an epoch not
        among them is computed alone. Forgotten at the end of the batch.
        """
        if self._iod_rotations is None:
            pending = [m.t for init in self._initiators.values() for m in init.batch]
            epochs = np.unique(np.r_[self._batch_t[np.isfinite(self._batch_t)],
                                     pending]) + self._unix0
            self._iod_rotations = epochs, frames.gcrs_to_itrs_matrix(epochs)
        epochs, g = self._iod_rotations
        t = np.asarray(t_unix, dtype=float).reshape(-1)
        i = np.minimum(np.searchsorted(epochs, t), max(epochs.size - 1, 0))
        hit = epochs[i] == t if epochs.size else np.zeros(t.size, dtype=bool)
        out = np.array([g[k] if h else frames.gcrs_to_itrs_matrix(tk)
                        for k, h, tk in zip(i.tolist(), hit.tolist(), t.tolist(), strict=True)])
        return np.swapaxes(out, -1, -2)

    def warm_up(self) -> None:
        """Load the compiled code of `process` now rather than in the first batch.

        The EKF cycle's (`batch_ekf.BatchEKF.warm_up`) and the IOD's motion model, on one
        made-up object; nothing is kept.
        """
        self.ekf.warm_up()
        self._placeholder(np.array([7000.0, 0.0, 0.0, 0.0, 7.5, 0.0]), 60.0, 0.0)

    def __len__(self) -> int:
        """Return the number of objects heard of."""
        return len(self.object_ids)

    @property
    def pending_iod(self) -> int:
        """Return the number of measurements waiting in IOD batches (objects without a track)."""
        return sum(len(init.batch) for init in self._initiators.values())

    @property
    def nbytes(self) -> int:
        """Return the bytes of what the bank holds per object (B).

        Its per-object arrays (all rows of their capacity) and the measurements waiting in
        IOD batches (each its object, z and R: `sys.getsizeof`); not the dictionaries of
        ids and rows, nor the shared models.
        """
        arrays = (self.x, self.P, self.t, self.tracking, self.gate_misses, self.stations_at_t,
                  self.seen)
        pending = sum(sys.getsizeof(m) + sys.getsizeof(m.__dict__) + m.z.nbytes + m.R.nbytes
                      for init in self._initiators.values() for m in init.batch)
        return sum(a.nbytes for a in arrays) + pending

    def _placeholder(self, x: np.ndarray, dt: float,
                     t0: float) -> tuple[np.ndarray, np.ndarray]:
        """Propagate one state at `t0` by the motion model: (x, F) `dt` s later (for the IOD)."""
        x1, F, _ = self.ekf.propagate(np.asarray(x, dtype=float)[None], np.array([dt]),
                                      np.array([t0]))
        return x1[0], F[0]

    def _placeholder_many(self, x: np.ndarray, dt: np.ndarray,
                          t0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Move K states (K, 6) as `_placeholder` moves one: (x (K, 6), F (K, 6, 6))."""
        x1, F, _ = self.ekf.propagate(np.asarray(x, dtype=float), np.asarray(dt, dtype=float),
                                      np.asarray(t0, dtype=float))
        return x1, F

    def row(self, object_id: str, t: float = -math.inf) -> int:
        """Return the row of `object_id`, added (without a track) when new.

        `t`: the epoch of the measurement asking (s). A new object in a full bank takes the
        row of the object measured longest ago if that was more than `evict_after_s`
        before `t`; else -1.
        """
        r = self.rows.get(object_id)
        if r is None and len(self.object_ids) >= self.max_objects:
            return self._evict(object_id, t)
        if r is None:
            r = self.rows[object_id] = len(self.object_ids)
            self.object_ids.append(object_id)
            if r >= self.t.size:
                grow = self.t.size
                self.x = np.concatenate([self.x, np.zeros((grow, 6))])
                self.P = np.concatenate([self.P, np.zeros((grow, 6, 6))])
                self.t = np.concatenate([self.t, np.full(grow, -math.inf)])
                self.tracking = np.concatenate([self.tracking, np.zeros(grow, dtype=bool)])
                self.gate_misses = np.concatenate([self.gate_misses,
                                                   np.zeros(grow, dtype=np.int64)])
                self.stations_at_t = np.concatenate([self.stations_at_t,
                                                     np.zeros(grow, dtype=np.uint64)])
                self.seen = np.concatenate([self.seen, np.full(grow, -math.inf)])
            self.seen[r] = t if math.isfinite(t) else -math.inf
        return r

    def _evict(self, object_id: str, t: float) -> int:
        """Give the row of the object measured longest ago to `object_id`, or return -1."""
        n = len(self.object_ids)
        old = int(np.argmin(self.seen[:n]))
        if not (math.isfinite(t) and t - self.seen[old] > self.evict_after_s):
            return -1
        del self.rows[self.object_ids[old]]
        self.object_ids[old] = object_id
        self.rows[object_id] = old
        self.x[old], self.P[old], self.t[old] = 0.0, 0.0, -math.inf
        self.tracking[old], self.gate_misses[old], self.stations_at_t[old] = False, 0, 0
        self.seen[old] = t
        self._initiators.pop(old, None)
        self.evicted += 1
        return old

    def process(self, t: ArrayLike, object_ids: Sequence[str], frame_ids: Sequence[str],
                z: ArrayLike, R: ArrayLike) -> BankResult:
        """Fuse a batch of M range/az/el measurements (module docstring).

        Parameters
        ----------
        t : array_like (M,)
            Epochs, Unix s, non-decreasing.
        object_ids, frame_ids : sequence of str (M,)
            The object measured and the station measuring it (an id of the network).
        z : array_like (M, 3)
            Range km, azimuth rad, elevation rad.
        R : array_like (M, 3, 3)
            Noise covariances, km^2, rad^2.
        """
        tt = np.array(t, dtype=float)  # copies: the caller's arrays may change later
        zz = np.array(z, dtype=float).reshape(-1, 3)
        RR = np.array(R, dtype=float).reshape(-1, 3, 3)
        self._batch_t, self._iod_rotations = tt, None
        batch = self._admit(tt, zz, RR, object_ids, frame_ids)
        for idx in _rounds(batch.rows, batch.station):
            idx = self._start_tracks(batch, idx)
            if idx.size:
                self._fuse_round(batch, idx)
        self._batch_t, self._iod_rotations = np.zeros(0), None  # not a view: tt goes
        return batch.result()

    def _admit(self, tt: Array, zz: Array, RR: Array, object_ids: Sequence[str],
               frame_ids: Sequence[str]) -> _Batch:
        """Return the batch with its rows (new objects given one), stations, early rejections.

        A measurement of an unknown station, of a full bank or at a non-finite epoch is
        rejected here (its station set to -1: out of every round).
        """
        m = tt.size
        known = np.fromiter(map(self.rows.get, object_ids, repeat(-1, m)), np.int64, m)
        ok = (known >= 0) & np.isfinite(tt)
        np.maximum.at(self.seen, known[ok], tt[ok])  # before any eviction: this batch's
        rows = known.copy()
        for i in np.flatnonzero(known < 0).tolist():  # new objects, in batch order
            rows[i] = self.row(object_ids[i], float(tt[i]))
        station = np.fromiter(map(self.ekf.index.get, frame_ids, repeat(-1, m)), np.int64, m)
        cause = [""] * m
        for i in np.flatnonzero(station < 0).tolist():
            cause[i] = Cause.REJECTED_FRAME
        for i in np.flatnonzero(rows < 0).tolist():
            cause[i] = Cause.REJECTED_BANK_FULL
            station[i] = -1  # out of every round
        for i in np.flatnonzero(~np.isfinite(tt)).tolist():
            cause[i] = Cause.REJECTED_NONFINITE
            station[i] = -1  # out of every round
        return _Batch(tt, zz, RR, object_ids, frame_ids, rows, station, cause)

    def _start_tracks(self, batch: _Batch, idx: NDArray[np.int64]) -> NDArray[np.int64]:
        """Feed a round's untracked objects to their IODs (solved at once): the tracked rest."""
        tracked = self.tracking[batch.rows[idx]]
        waiting = idx[~tracked].tolist()  # initial orbit determination, solved at once
        answers = self._initiate_many([int(batch.rows[i]) for i in waiting],
                                      [batch.measurement(i) for i in waiting])
        for i, started in zip(waiting, answers, strict=True):
            if isinstance(started, str):
                batch.cause[i] = started
            else:
                batch.emit(np.array([i]), started.x[None], started.P[None], np.zeros(1))
        out: NDArray[np.int64] = idx[tracked]
        return out

    def _fuse_round(self, batch: _Batch, idx: NDArray[np.int64]) -> None:
        """Predict and fuse one round's measurements of tracked objects (`BatchEKF.step`).

        Stale and duplicate measurements are rejected; a track beyond its gate
        ``reinit_after`` times in a row starts its IOD again (`_reinitialise`).
        """
        tt, cause = batch.t, batch.cause
        r = batch.rows[idx]
        dt = tt[idx] - self.t[r]
        bit = station_bit(batch.station[idx])
        again = (dt == 0) & ((self.stations_at_t[r] & bit) != 0)
        for i in idx[dt < 0].tolist():
            cause[i] = Cause.REJECTED_STALE
        for i in idx[again].tolist():
            cause[i] = Cause.REJECTED_DUPLICATE
        go = (dt > 0) | ((dt == 0) & ~again)
        idx, r, dt, bit = idx[go], r[go], dt[go], bit[go]
        if not idx.size:
            return
        if batch.rot is None:  # the batch's, at its first round
            batch.rot = self.ekf.rotations(tt)
        res = self.ekf.step(self.x[r], self.P[r], dt, batch.z[idx], batch.R[idx], tt[idx],
                            batch.station[idx], rotations=(batch.rot[0], batch.rot[1][idx]))
        ok = res.code == Code.FUSED
        for i, c in zip(idx[~ok].tolist(), res.code[~ok].tolist(), strict=True):
            cause[i] = REASONS[c]
        gate = res.code == Code.GATE
        self.gate_misses[r[ok]] = 0
        self.gate_misses[r[gate]] += 1
        limit = self.config.iod.reinit_after
        if limit:
            for i in idx[gate & (self.gate_misses[r] >= limit)].tolist():
                cause[i] = self._reinitialise(int(batch.rows[i]), batch.measurement(i))
        if not ok.all():  # as a rule every one is fused: no copies then
            idx, r, dt, bit = idx[ok], r[ok], dt[ok], bit[ok]
            res = res._replace(x=res.x[ok], P=res.P[ok], nis=res.nis[ok])
        self.x[r] = res.x
        self.P[r] = res.P
        self.stations_at_t[r] = np.where(dt == 0, self.stations_at_t[r], 0) | bit
        self.t[r] = tt[idx]
        batch.emit(idx, res.x, res.P, res.nis)

    def _reinitialise(self, row: int, m: Measurement) -> str:
        """Drop the row's track (it lost its object) and start its IOD again from `m`."""
        self.tracking[row] = False
        self.t[row] = -math.inf
        self.stations_at_t[row] = 0
        self.gate_misses[row] = 0
        self._initiators.pop(row, None)
        self._initiate(row, m)
        return Cause.REINITIALISED

    def _initiate(self, row: int, m: Measurement) -> InitialState | str:
        """Feed `m` to the row's initiator: the initial state once solved, else the cause."""
        return self._initiate_many([row], [m])[0]

    def _initiate_many(self, rows: list[int], ms: list[Measurement]) -> list[InitialState | str]:
        """`_initiate` of distinct rows: the batches they complete solved at once.

        `initiation.finish_razel`: one vectorised solution and one propagation for all;
        each row's answer as `_initiate` alone would give it.
        """
        iod = self.config.iod
        answers: list[InitialState | str] = [Cause.IOD_PENDING] * len(rows)
        complete: list[int] = []
        initiators: list[OrbitInitiator] = []
        batches: list[list[Measurement]] = []
        for k, (row, m) in enumerate(zip(rows, ms, strict=True)):
            init = self._initiators.get(row)
            if init is None:
                init = self._initiators[row] = OrbitInitiator(
                    self._placeholder, self.models, 6, self._iod_to_gcrs)
            got = init.collect(m, iod.iod_samples, iod.iod_max_span_s)
            if isinstance(got, tuple):
                answers[k] = got[0]
            else:
                complete.append(k)
                initiators.append(init)
                batches.append(got)
        if not complete:
            return answers
        solved = finish_razel(initiators, batches, iod.p0_sigma, self._placeholder_many,
                              self._iod_to_gcrs)
        for k, out in zip(complete, solved, strict=True):
            if isinstance(out, tuple):
                answers[k] = out[0]
                continue
            row = rows[k]
            del self._initiators[row]
            self.x[row], self.P[row], self.t[row] = out.x, out.P, out.t
            self.stations_at_t[row] = station_bit(np.array([self.ekf.index[ms[k].frame_id]]))[0]
            self.tracking[row] = True
            answers[k] = out
        return answers
