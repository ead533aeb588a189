"""A decision deferred over passes: two hypotheses for an ambiguous pair of young tracks.

Objects launched together are a few km apart. In its second pass a track's orbit comes from
one pass (an IOD and a short filtered arc), and its along-track prediction 1.5 h later errs
by about a km, independently per track: the scan-wise global nearest neighbour
(`assignment.assign`) can give two neighbours each other's detections, and each track's
filter then follows its new object. Within that pass both assignments fit: it is the next
pass that tells them apart, since an orbit fitted to one object's first pass and its
neighbour's second has the wrong mean motion, and predicts the third pass km off.

`PairDeferral` keeps both hypotheses for such a pair (tracks ``a`` and ``b``, bank rows):

* *opening* (`ambiguous_pairs`): in a scan where both tracks got a detection, the pair is
  ambiguous when the swapped assignment costs at most ``margin`` more than the chosen one
  (costs ``d^2 + ln det S`` of `gating.gate_scan`: twice the negative
  log-likelihood, so ``margin`` = 2 ln(ratio) admits a swapped hypothesis at least
  1/ratio as likely) and both swapped pairs are inside the gate. The hypothesis H0 is what
  the association does (the real tracks, fused as assigned); the hypothesis H1 is the
  pair's detections exchanged from that scan to the end of the pass, fused into *shadow*
  copies of the two tracks (their states before the scan; `TrackBank` rows under ids not
  known to the association, in a bank of the tracks' filter and one of the long-arc
  predictor's);
* *scoring*: each scan of the pass adds to each hypothesis the costs of its two tracks'
  detections on their own predictions (the scoring filter: the long-arc predictor when
  there is one, else the tracks' filter), ``min(d^2, gate) + ln det S`` per track (a track
  without a detection, or with one outside its gate, costs the gate: a miss);
* *decision*: at the first scan after the pass (``pass_gap_s`` without a detection of the
  pair) in which both tracks of the pair, in either hypothesis, get a detection inside the
  gate, each hypothesis is scored on that whole scan as the association would make it
  with the pair's tracks in its states (`manager.Associator._scan_cost`: every
  track's prediction, the long-arc rescoring, the groups' registration, the assignment;
  ``min(d^2, gate) + ln det S`` per track, the gate for a track without a detection).
  Across a long gap the pair's own predictions share an along-track error of km with
  their group, which the registration takes out; a track of the wrong hypothesis (an
  orbit fitted to one object's first pass and its neighbour's second) is then km off its
  group, and pushes its neighbours off theirs in the assignment. The hypothesis of least
  total cost (the deferred pass's and that scan's) wins. When it is H1, the shadows'
  states replace the tracks' (both filters) and every detection of the pair in the
  deferred pass changes label (`Relabel`): the tracks stay on the objects of their first
  pass. Then the scan is associated as usual.

A fork whose track is deleted, or whose pair is not seen again within
``defer_max_wait_s`` of its pass (`config.AssociationConfig`), is dropped (H0 stays).
Units: the core's (km, rad, s).
"""

from __future__ import annotations

import enum
import math
from collections import Counter
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.catalog.association.assignment import UNASSIGNED, assign
from ssa_fusion.core.catalog.association.gating import gate_scan, predict_scan
from ssa_fusion.core.catalog.association.outcomes import Relabel, TrackEvent
from ssa_fusion.core.catalog.track_bank import TrackBank
from ssa_fusion.core.earth.frames import Station
from ssa_fusion.core.filter.options import FilterOptions

__all__ = ["Fork", "ForkState", "PairDeferral", "ambiguous_pairs", "copy_track", "pair_cost",
           "shadows_in"]

Array = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.int64]
Filters = list[tuple[TrackBank, int, int]]
"""Per filter (the tracks', then the long-arc predictor's), its bank and the rows of a fork's
two tracks in it."""
ScanCost = tuple[float, IntArray, Array]
"""A whole scan associated as the association would (`manager.Associator._scan_cost`): its
total cost, per detection its track's index, per track the ``d^2`` of its detection."""


class ForkState(enum.IntEnum):
    """Where a deferred decision stands."""

    OPEN = 0
    """In the ambiguous pass: both hypotheses are fused and scored."""
    PENDING = 1
    """The pass ended: decided at the next scan that sees the pair."""


@dataclass
class Fork:
    """Two hypotheses for the tracks of bank rows ``a`` and ``b`` (module docstring).

    Attributes
    ----------
    a, b : int
        The tracks' rows in the associator's bank.
    shadow : tuple of str
        Ids of H1's tracks in the shadow banks: a's state with b's detections, and b's
        with a's.
    t_last : float
        The last scan, Unix s, in which the pair got a detection.
    cost : ndarray (2,)
        Accumulated cost of H0 and H1 (``d^2 + ln det S`` units).
    labels : list of (int, int, str)
        (scan, detection, id under H1) of the pair's detections in the deferred pass.
    """

    a: int
    b: int
    shadow: tuple[str, str]
    t_last: float
    cost: Array = field(default_factory=lambda: np.zeros(2))
    labels: list[tuple[int, int, str]] = field(default_factory=list)
    state: ForkState = ForkState.OPEN


def ambiguous_pairs(track: IntArray, cost: Array, feasible: BoolArray, margin: float,
                    eligible: BoolArray) -> list[tuple[int, int]]:
    """Return the ambiguous pairs of a scan's assignment (module docstring), least first.

    Parameters
    ----------
    track : ndarray (M,) of int
        Per detection its track (row of `cost`) or `assignment.UNASSIGNED` (-1).
    cost, feasible : ndarray (N, M)
        The costs and the gate the assignment was made with.
    margin : float
        Largest extra cost of the swapped assignment of two tracks (``d^2 + ln det S``
        units) for which they are ambiguous.
    eligible : ndarray (N,) of bool
        The tracks that may be paired.

    Returns
    -------
    list of (int, int)
        Pairs of rows of `cost`, each row in one pair at most, by increasing extra cost.
    """
    det = np.flatnonzero(track >= 0)
    det = det[eligible[track[det]]]
    if det.size < 2:
        return []
    r = track[det]
    c = cost[np.ix_(r, det)]  # (K, K): track r_i on detection det_k
    f = feasible[np.ix_(r, det)]
    own = np.diag(c)
    extra = c + c.T - own[:, None] - own[None, :]
    ok = f & f.T & np.triu(np.ones(extra.shape, dtype=bool), 1) & (extra <= margin)
    i, k = np.nonzero(ok)
    out: list[tuple[int, int]] = []
    used: set[int] = set()
    for n in np.argsort(extra[i, k], kind="stable").tolist():
        ri, rk = int(r[i[n]]), int(r[k[n]])
        if ri not in used and rk not in used:
            out.append((ri, rk))
            used.update((ri, rk))
    return out


def pair_cost(bank: TrackBank, rows: ArrayLike, station: int, t: Array, z: Array, R: Array,
              gate: float, dets: ArrayLike | None = None) -> tuple[float, bool]:
    """Cost of K tracks of a bank on a scan's detections (a deferred decision's score).

    Each track costs ``min(d^2, gate) + ln det S`` on its detection (the cost of
    `gating.gate_scan` with ``d^2`` clipped at the gate), or ``gate + ln det S`` (S at the scan's
    first epoch) without one: a detection outside the gate counts as a miss.

    Parameters
    ----------
    bank : TrackBank
        Holds the tracks.
    rows : array_like (K,) of int
        Their rows in ``bank``.
    station : int
        Index of the scanning station in ``bank.ekf.stations``.
    t, z, R : ndarray (M,), (M, 3), (M, 3, 3)
        The scan's epochs (Unix s), detections and their noise (as `gating.gate_scan`).
    gate : float
        Threshold on ``d^2`` (`AssociationConfig.gate`).
    dets : array_like (K,) of int, optional
        Each track's detection (-1: none); default: the tracks' own best assignment of the
        scan (`assignment.assign` on their K x M costs).

    Returns
    -------
    (float, bool)
        The total cost, and whether any (track, detection) pair is inside the gate.
    """
    r = np.asarray(rows, dtype=np.int64)
    pred = predict_scan(bank.ekf, bank.x[r], bank.P[r], bank.t[r], t, station)
    g = gate_scan(pred, z, R, gate)
    if dets is None:
        det_track = assign(g.cost, g.feasible)
        d = np.full(r.size, UNASSIGNED, dtype=np.int64)
        got = np.flatnonzero(det_track >= 0)
        d[det_track[got]] = got
    else:
        d = np.asarray(dets, dtype=np.int64)
    S0 = pred.HPHt[0] + np.asarray(R, dtype=float).reshape(-1, 3, 3)[0]
    sign, miss_logdet = np.linalg.slogdet(S0)
    total = 0.0
    for i, j in enumerate(d.tolist()):
        if j >= 0 and math.isfinite(g.d2[i, j]):
            total += min(float(g.d2[i, j]), gate) + float(g.cost[i, j] - g.d2[i, j])
        else:
            total += gate + (float(miss_logdet[i]) if sign[i] > 0 else 0.0)
    return total, bool(g.feasible.any())




_TRACK_FIELDS = ("x", "P", "t", "tracking", "gate_misses", "stations_at_t", "seen")
"""The per-row arrays of a `TrackBank` that hold one track's filter state."""


def copy_track(src: TrackBank, row: int, dst: TrackBank, dst_row: int) -> None:
    """Copy one track's state, covariance, epoch and fusion marks between banks."""
    dst.x[dst_row], dst.P[dst_row], dst.t[dst_row] = src.x[row], src.P[row], src.t[row]
    dst.tracking[dst_row] = src.tracking[row]
    dst.gate_misses[dst_row] = 0
    dst.stations_at_t[dst_row] = src.stations_at_t[row]
    dst.seen[dst_row] = src.seen[row]


@contextmanager
def shadows_in(fork: Fork, filters: Filters,
               shadows: list[TrackBank]) -> Iterator[None]:
    """Within the block, the tracks of ``fork`` hold H1's states; restored after it.

    ``filters``: per filter (the tracks', then the long-arc predictor's), the bank and the
    rows of ``fork.a`` and ``fork.b`` in it; ``shadows``: the shadow banks in the same
    order (`PairDeferral.banks`). Row ``a`` takes shadow 0 (a's state with b's
    detections), row ``b`` shadow 1.
    """
    saved = []
    for (bank, ra, rb), dst in zip(filters, shadows, strict=True):
        for r, name in ((ra, fork.shadow[0]), (rb, fork.shadow[1])):
            saved.append((bank, r, [getattr(bank, f)[r].copy() for f in _TRACK_FIELDS]))
            copy_track(dst, dst.rows[name], bank, r)
    try:
        yield
    finally:
        for bank, r, values in saved:
            for f, v in zip(_TRACK_FIELDS, values, strict=True):
                getattr(bank, f)[r] = v


class PairDeferral:
    """The open forks of an associator and their shadow tracks (module docstring).

    Parameters
    ----------
    options : FilterOptions
        The tracks' filter.
    predictor_options : FilterOptions or None
        The long-arc predictor's filter; None without one.
    stations : dict of str to Station
        The network.
    gate : float
        Threshold on ``d^2`` (`config.AssociationConfig.gate`).
    pass_gap_s : float
        A pair without a detection for longer than this, s, ended its pass.
    """

    def __init__(self, options: FilterOptions, predictor_options: FilterOptions | None,
                 stations: dict[str, Station], gate: float, pass_gap_s: float) -> None:
        self.shadow = TrackBank(options, stations)
        self.shadow_predictor = (None if predictor_options is None
                                 else TrackBank(predictor_options, stations))
        self.gate = float(gate)
        self.pass_gap_s = float(pass_gap_s)
        self.forks: list[Fork] = []
        self._serial = 0

    def busy(self) -> set[int]:
        """Return the bank rows in an open or pending fork."""
        return {r for f in self.forks for r in (f.a, f.b)}

    def scans_held(self) -> set[int]:
        """Return the serial numbers of the scans whose detections a fork may relabel."""
        return {lab[0] for f in self.forks for lab in f.labels}

    def open(self, a: int, b: int, t_scan: float, banks: Filters) -> Fork:
        """Start a fork for rows ``a``, ``b``: shadows of their states before this scan.

        ``banks``: per filter (the tracks', then the long-arc predictor's), the bank and
        the rows of ``a`` and ``b`` in it.
        """
        self._serial += 1
        bank = banks[0][0]
        names = (f"{bank.object_ids[b]}~{self._serial}", f"{bank.object_ids[a]}~{self._serial}")
        # shadow 0 is track a's state with b's detections; shadow 1 is b's with a's
        for (src, ra, rb), dst in zip(banks, self.banks(), strict=False):
            for name, r in zip(names, (ra, rb), strict=True):
                copy_track(src, r, dst, dst.row(name))
        fork = Fork(a, b, names, t_scan)
        self.forks.append(fork)
        return fork

    def banks(self) -> list[TrackBank]:
        """Return the shadow banks: the tracks' filter's, then the long-arc predictor's."""
        return [self.shadow] + ([] if self.shadow_predictor is None else [self.shadow_predictor])

    def scoring_shadow(self) -> TrackBank:
        """Return the shadow bank of the scoring filter (the long-arc predictor's if any)."""
        return self.shadow_predictor if self.shadow_predictor is not None else self.shadow

    def fuse_shadows(self, fork: Fork, t: Array, station: str, z: Array, R: Array,
                     dets: tuple[int, int]) -> None:
        """Fuse H1's detections into the shadows: ``dets`` = (a's, b's) under H0 (-1: none).

        Shadow 0 (a's state) takes b's detection, shadow 1 takes a's.
        """
        pick = [(fork.shadow[0], dets[1]), (fork.shadow[1], dets[0])]
        pick = sorted([p for p in pick if p[1] >= 0], key=lambda p: float(t[p[1]]))
        if not pick:
            return
        j = [p[1] for p in pick]
        for dst in self.banks():
            dst.process(t[j], [p[0] for p in pick], [station] * len(j), z[j], R[j])

    def score(self, rows: IntArray, track: IntArray, scoring: tuple[TrackBank, IntArray],
              station: str, st: int, t_scan: float, t: Array, z: Array, R: Array,
              scan: int, names: list[str]) -> None:
        """Score both hypotheses of the open forks on a scan; fuse H1 into the shadows.

        Parameters
        ----------
        rows : ndarray (N,) of int
            The bank rows of the tracks the scan was associated with.
        track : ndarray (M,) of int
            Per detection its index in ``rows``, or `assignment.UNASSIGNED`.
        scoring : (TrackBank, ndarray of int)
            The scoring filter (the long-arc predictor if any, else the tracks') and each
            bank row's row in it (-1: none).
        station, st : str, int
            The scanning station's id and index in the banks' filter.
        t_scan : float
            The scan's epoch, Unix s.
        t, z, R : ndarray (M,), (M, 3), (M, 3, 3)
            The scan's epochs, detections and their noise (as `gating.gate_scan`).
        scan : int
            The scan's serial number (`outcomes.Relabel`).
        names : list of str
            The track id of each bank row.
        """
        src, srow = scoring
        local = {int(r): i for i, r in enumerate(rows.tolist())}
        shadow = self.scoring_shadow()
        for fork in self.forks:
            if fork.state != ForkState.OPEN or fork.a not in local or fork.b not in local:
                continue
            da, db = (int(np.flatnonzero(track == local[r])[0]) if (track == local[r]).any()
                      else UNASSIGNED for r in (fork.a, fork.b))
            if da == UNASSIGNED and db == UNASSIGNED:
                continue
            h0, _ = pair_cost(src, srow[[fork.a, fork.b]], st, t, z, R, self.gate, [da, db])
            h1, _ = pair_cost(shadow, [shadow.rows[n] for n in fork.shadow], st, t, z, R,
                              self.gate, [db, da])
            fork.cost += (h0, h1)
            fork.labels += [(scan, j, names[r]) for j, r in ((da, fork.b), (db, fork.a))
                            if j != UNASSIGNED]
            fork.t_last = t_scan
            self.fuse_shadows(fork, t, station, z, R, (da, db))

    def decide(self, t_scan: float, deleted: BoolArray, max_wait_s: float, rows: IntArray,
               bank: TrackBank, st: int, t: Array, z: Array, R: Array,
               scan_cost: Callable[[], ScanCost], filters: Callable[[int, int], Filters],
               counts: Counter[TrackEvent]) -> list[Relabel]:
        """Decide the forks whose pass ended, on this scan (module docstring).

        Each hypothesis is scored on the whole scan as the association would make it
        (``scan_cost``: every track's prediction, the long-arc rescoring, the groups'
        registration and the assignment), with the pair's tracks in H0's states (the
        tracks') or H1's (the shadows'): after a long gap the pair's own predictions share
        an along-track error of km with their group, which the registration takes out.

        Parameters
        ----------
        t_scan : float
            The scan's epoch, Unix s.
        deleted : ndarray of bool
            Per bank row, whether its track was deleted (its forks are dropped).
        max_wait_s : float
            `config.AssociationConfig.defer_max_wait_s`.
        rows : ndarray (N,) of int
            The bank rows of the tracks the scan is associated with.
        bank : TrackBank
            The tracks' bank.
        st : int
            The scanning station's index in the bank's filter.
        t, z, R : ndarray (M,), (M, 3), (M, 3, 3)
            The scan (as `score`).
        scan_cost : callable
            The scan associated with the tracks as they are now (`ScanCost`).
        filters : callable
            ``filters(a, b)``: the `Filters` of bank rows a, b.
        counts : Counter of TrackEvent
            Where the dropped, swapped and kept decisions are counted.

        Returns
        -------
        list of Relabel
            The detections of the deferred passes whose track changed.
        """
        keep, ready = self._due(t_scan, deleted, max_wait_s, counts)
        local = {int(r): i for i, r in enumerate(rows.tolist())}
        relabels: list[Relabel] = []
        h0: ScanCost | None = None
        for fork in ready:
            if fork.a not in local or fork.b not in local:
                counts[TrackEvent.DEFER_DROPPED] += 1
                continue
            if not self._in_gates(fork, bank, st, t, z, R):
                keep.append(fork)  # the pair is not in this scan's gates
                continue
            if h0 is None:  # H0 of every fork: the tracks as they are
                h0 = scan_cost()
            held = filters(fork.a, fork.b)
            with shadows_in(fork, held, self.banks()):
                h1 = scan_cost()
            pair = [local[fork.a], local[fork.b]]
            if not any((h[2][pair] <= self.gate).all() for h in (h0, h1)):
                keep.append(fork)  # no hypothesis has both tracks in the scan yet
                continue
            if fork.cost[1] + h1[0] < fork.cost[0] + h0[0]:
                for (held_bank, ra, rb), dst in zip(held, self.banks(), strict=True):
                    copy_track(dst, dst.rows[fork.shadow[0]], held_bank, ra)
                    copy_track(dst, dst.rows[fork.shadow[1]], held_bank, rb)
                relabels += [Relabel(*lab) for lab in fork.labels]
                counts[TrackEvent.DEFER_SWAPPED] += 1
                h0 = None  # the tracks changed
            else:
                counts[TrackEvent.DEFER_KEPT] += 1
        self.forks = keep
        return relabels

    def _due(self, t_scan: float, deleted: BoolArray, max_wait_s: float,
             counts: Counter[TrackEvent]) -> tuple[list[Fork], list[Fork]]:
        """Split the forks into those kept as they are and those ready for a decision.

        A fork of a deleted track, or whose pair was not seen within ``max_wait_s`` after
        its pass, is dropped (counted); an open fork whose pass ended becomes pending.
        """
        keep, ready = [], []
        for fork in self.forks:
            if deleted[fork.a] or deleted[fork.b]:
                counts[TrackEvent.DEFER_DROPPED] += 1
                continue
            if fork.state == ForkState.OPEN and t_scan - fork.t_last > self.pass_gap_s:
                fork.state = ForkState.PENDING
            if fork.state != ForkState.PENDING:
                keep.append(fork)
                continue
            if t_scan - fork.t_last > max_wait_s:
                counts[TrackEvent.DEFER_DROPPED] += 1
                continue
            ready.append(fork)
        return keep, ready

    def _in_gates(self, fork: Fork, bank: TrackBank, st: int, t: Array, z: Array,
                  R: Array) -> bool:
        """Whether the fork's pair, in either hypothesis, gates a detection of the scan."""
        shadow = self.shadow
        return (pair_cost(bank, [fork.a, fork.b], st, t, z, R, self.gate)[1]
                or pair_cost(shadow, [shadow.rows[n] for n in fork.shadow], st, t, z, R,
                             self.gate)[1])
