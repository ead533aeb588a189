"""Track management: a catalog of unlabelled objects, scan by scan (`Associator`).

* Every scan is first associated with the tracks (tentative and confirmed, the rows of a
  `track_bank.TrackBank` named by track ids "T1", "T2", ...): predicted and gated
  (`gating`), rescored by the long-arc predictor and registered in groups
  (`registration`), assigned (`assignment`); each assigned detection is fused by the bank
  under its track's id.
* The detections no track took extend or start tracklets (`tracklets`). A tracklet of
  ``iod_samples`` detections (the bank's `filter_options.IodOptions`) is handed to the
  bank under a new track id: its initial orbit determination (Herrick-Gibbs over the
  pass, `initiation.OrbitInitiator`) starts a *tentative* track.
* A tentative track is *confirmed* after ``confirm_hits`` detections in its last
  ``confirm_window`` expected scans (M of N; expected: predicted above the scanning
  sensor's mask), and deleted once it can no longer be (``confirm_window`` expected scans
  with fewer hits). Any track is deleted after ``delete_after_missed_passes`` passes in a
  row in which it was expected and got nothing, or when its predicted position standard
  deviation exceeds ``max_position_sigma_km``.
* Ambiguous pairs of young tracks keep both hypotheses until the next pass (`deferral`).
* `outcomes.TrackEvent` counts each outcome; `Associator.counts` holds the counters.

Deleted tracks keep their bank rows (never reused): a bank holds at most
``max_objects`` rows (`validation.MAX_OBJECTS`) over its life. Units: km, km/s, rad, s
(Unix s UTC), GCRF.
"""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.catalog.association.assignment import assign
from ssa_fusion.core.catalog.association.config import AssociationConfig
from ssa_fusion.core.catalog.association.deferral import (
    Filters,
    PairDeferral,
    ScanCost,
    ambiguous_pairs,
)
from ssa_fusion.core.catalog.association.gating import (
    Gated,
    ScanPrediction,
    gate_long_arc,
    gate_scan,
    predict_scan,
)
from ssa_fusion.core.catalog.association.outcomes import (
    DetectionFate,
    Relabel,
    ScanOutcome,
    TrackEvent,
    TrackStatus,
)
from ssa_fusion.core.catalog.association.registration import linked_tracks, register
from ssa_fusion.core.catalog.association.tracklets import (
    Detection,
    Tracklets,
    detection_positions,
)
from ssa_fusion.core.catalog.track_bank import TrackBank
from ssa_fusion.core.earth.frames import Station
from ssa_fusion.core.filter.options import FilterOptions

__all__ = ["Associator"]

Array = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.int64]


def _popcount(bits: IntArray, width: int) -> IntArray:
    """Return the number of set bits among the low `width` bits of each element."""
    out = np.zeros(bits.shape, dtype=np.int64)
    for k in range(width):  # over the bits, not the tracks
        out += (bits >> k) & 1
    return out



class Associator:
    """Tracks of unlabelled objects from scans of detections (module docstring).

    Parameters
    ----------
    filter_options : FilterOptions
        The tracks' filter (`track_bank.TrackBank`; its ``reinit_after`` is set to 0: a
        track that loses its object is deleted here, not initialised again from a detection
        that may be another object's).
    stations : dict of str to Station
        The network: a scan names its station by id.
    config : AssociationConfig
        Gate and track-management rules.
    """

    def __init__(self, filter_options: FilterOptions, stations: dict[str, Station],
                 config: AssociationConfig | None = None) -> None:
        self.config = AssociationConfig() if config is None else config
        options = filter_options.with_(reinit_after=0)
        self.bank = TrackBank(options, stations)
        q = self.config.predictor_q
        self.predictor = None if q is None else TrackBank(options.with_(q=q), stations)
        """The long-arc predictor (`AssociationConfig.predictor_q`): the same tracks, fed the
        same detections, whose predictions score the pairs; None without one."""
        self.stations = dict(stations)
        self.deferral = None if not self.config.defer_passes else PairDeferral(
            options, None if q is None else options.with_(q=q), self.stations,
            self.config.gate, self.config.pass_gap_s)
        """The deferred decisions (`AssociationConfig.defer_passes`); None without them."""
        self.relabels: list[Relabel] = []
        """Every detection whose track a deferred decision changed (`ScanOutcome`)."""
        self.iod_samples = int(options.iod.iod_samples)
        self.counts: Counter[TrackEvent] = Counter()
        self._gate = self.config.gate
        # per bank row (grown with the bank)
        self.status = np.zeros(0, dtype=np.int8)
        self._bits = np.zeros(0, dtype=np.int64)
        self._expected = np.zeros(0, dtype=np.int64)
        self._last_expected = np.zeros(0)
        self._pass_open = np.zeros(0, dtype=bool)
        self._pass_hits = np.zeros(0, dtype=np.int64)
        self._missed = np.zeros(0, dtype=np.int64)
        self._passes = np.zeros(0, dtype=np.int64)  # passes ended with a detection
        self._prow = np.zeros(0, dtype=np.int64)  # the row in `predictor`, -1: none
        self._scan = -1  # serial number of the scan being processed
        self.tracklets = Tracklets(self.config)
        """The open tracklets (`tracklets.Tracklets`)."""

    # --------------------------------------------------------------------------------------
    @property
    def scan_serial(self) -> int:
        """Serial number of the last scan processed (0 for the first; -1 before it)."""
        return self._scan

    def track_ids(self, status: TrackStatus) -> list[str]:
        """Return the ids of the tracks of a status."""
        return [self.bank.object_ids[r] for r in np.flatnonzero(self.status == status)]

    def _grow(self) -> None:
        """Per-track arrays as long as the bank."""
        extra = len(self.bank) - self.status.size
        if extra <= 0:
            return
        self.status = np.r_[self.status, np.full(extra, TrackStatus.TENTATIVE, np.int8)]
        self._bits = np.r_[self._bits, np.zeros(extra, np.int64)]
        self._expected = np.r_[self._expected, np.zeros(extra, np.int64)]
        self._last_expected = np.r_[self._last_expected, np.full(extra, -math.inf)]
        self._pass_open = np.r_[self._pass_open, np.zeros(extra, bool)]
        self._pass_hits = np.r_[self._pass_hits, np.zeros(extra, np.int64)]
        self._missed = np.r_[self._missed, np.zeros(extra, np.int64)]
        self._passes = np.r_[self._passes, np.zeros(extra, np.int64)]
        self._prow = np.r_[self._prow, np.full(extra, -1, np.int64)]

    def _delete(self, rows: IntArray, event: TrackEvent) -> None:
        self.status[rows] = TrackStatus.DELETED
        self.bank.tracking[rows] = False
        self.counts[event] += int(rows.size)

    # --------------------------------------------------------------------------------------
    def process_scan(self, station: str, t: ArrayLike, z: ArrayLike, R: ArrayLike,
                     min_elevation_rad: float) -> ScanOutcome:
        """Associate one station's scan, fuse it, and manage the tracks (module docstring).

        Parameters
        ----------
        station : str
            Id of the scanning station (a key of the network).
        t : array_like (M,) or scalar
            Epoch of each detection (or of the scan: a scalar, needed when M = 0), Unix s;
            scans come in epoch order.
        z : array_like (M, 3)
            Detections [range km, azimuth rad, elevation rad].
        R : array_like (M, 3, 3) or (3, 3)
            Their noise covariances, km^2, rad^2.
        min_elevation_rad : float
            The sensor's elevation mask, rad: a track predicted above it is expected in the
            scan (the sensor sees its whole sky above the mask).
        """
        zz = np.asarray(z, dtype=float).reshape(-1, 3)
        m = zz.shape[0]
        t_scan = float(np.min(t))
        tt = np.broadcast_to(np.asarray(t, dtype=float), (m,)).copy()
        RR = np.broadcast_to(np.asarray(R, dtype=float), (m, 3, 3)).copy()
        st = self.bank.ekf.index[station]
        self.counts[TrackEvent.SCANS] += 1
        self.counts[TrackEvent.DETECTIONS] += m
        self._scan += 1
        ids = [""] * m
        fate = np.full(m, DetectionFate.NEW_TRACKLET, dtype=np.int8)
        self._grow()
        self._expire(t_scan)
        done = len(self.relabels)
        if self.deferral is not None and m:
            self._decide(station, st, t_scan, tt, zz, RR)
        free = self._tracks(station, st, t_scan, tt, zz, RR, min_elevation_rad, ids, fate)
        self._tracklets(station, st, free, tt, zz, RR, ids, fate)
        self._grow()
        return ScanOutcome(ids, fate, tuple(self.relabels[done:]))


    def _tracks(self, station: str, st: int, t_scan: float, tt: Array, zz: Array,
                RR: Array, min_el: float, ids: list[str],
                fate: NDArray[np.int8]) -> IntArray:
        """Associate with the tracks, fuse, keep the counters: the free detections.

        A scan without detections (M = 0, at `t_scan`) still counts the tracks it
        expected as missed.
        """
        m = zz.shape[0]
        rows = self._active_rows()
        if not rows.size:
            return np.arange(m)
        bank = self.bank
        pred = predict_scan(bank.ekf, bank.x[rows], bank.P[rows], bank.t[rows],
                            tt if m else t_scan, st)
        track = np.zeros(0, dtype=np.int64)
        if m:
            gated = self._gate_scan(rows, pred, st, tt, zz, RR)
            track = assign(gated.cost, gated.feasible)
        sigma = pred.sigma_pos.max(0)
        lost = rows[sigma > self.config.max_position_sigma_km]
        got = track >= 0
        hit = np.zeros(rows.size, dtype=bool)
        hit[track[got]] = True
        expected = (pred.ok & (pred.zp[..., 2] >= min_el)).any(0) | hit
        if self.deferral is not None and m:
            self._defer(rows, track, gated, station, st, t_scan, tt, zz, RR)
        self._fuse(rows, track, station, tt, zz, RR, ids, fate)
        self._count_hits(rows[expected], hit[expected], t_scan)
        self._delete(lost[self.status[lost] != TrackStatus.DELETED],
                     TrackEvent.DELETED_COVARIANCE)
        return np.flatnonzero(~got)

    def _fuse(self, rows: IntArray, track: IntArray, station: str, tt: Array, zz: Array,
              RR: Array, ids: list[str], fate: NDArray[np.int8]) -> None:
        """Fuse the assigned detections (``track``: index in ``rows``), in epoch order."""
        bank = self.bank
        det = np.flatnonzero(track >= 0)
        det = det[np.argsort(tt[det], kind="stable")]
        names = [bank.object_ids[r] for r in rows[track[det]]]
        res = bank.process(tt[det], names, [station] * det.size, zz[det], RR[det])
        if self.predictor is not None and det.size:
            self.predictor.process(tt[det], names, [station] * det.size, zz[det], RR[det])
        refused = np.array([c != "" for c in res.cause], dtype=bool)
        for j, name in zip(det.tolist(), names, strict=True):
            ids[j] = name
        fate[det] = np.where(refused, DetectionFate.REFUSED, DetectionFate.TRACK)
        self.counts[TrackEvent.ASSIGNED] += int((~refused).sum())
        self.counts[TrackEvent.REFUSED] += int(refused.sum())

    def _count_hits(self, r_exp: IntArray, h_exp: BoolArray, t_scan: float) -> None:
        """Count passes and M of N of the tracks ``r_exp`` the scan expected (hit: ``h_exp``)."""
        cfg = self.config
        new_pass = t_scan - self._last_expected[r_exp] > cfg.pass_gap_s
        self._pass_hits[r_exp[new_pass]] = 0
        self._pass_open[r_exp] = True
        self._last_expected[r_exp] = t_scan
        self._pass_hits[r_exp] += h_exp
        width = cfg.confirm_window
        self._bits[r_exp] = ((self._bits[r_exp] << 1) | h_exp) & ((1 << width) - 1)
        self._expected[r_exp] += 1
        hits = _popcount(self._bits[r_exp], width)
        tentative = self.status[r_exp] == TrackStatus.TENTATIVE
        confirm = r_exp[tentative & (hits >= cfg.confirm_hits)]
        self.status[confirm] = TrackStatus.CONFIRMED
        self.counts[TrackEvent.TRACK_CONFIRMED] += int(confirm.size)
        hopeless = tentative & (hits < cfg.confirm_hits) & (self._expected[r_exp] >= width)
        self._delete(r_exp[hopeless], TrackEvent.TENTATIVE_DROPPED)

    # --------------------------------------------------------------------------------------
    def _scoring(self) -> tuple[TrackBank, IntArray]:
        """Return the scoring filter of deferred decisions and each track's row in it.

        The long-arc predictor if any, else the tracks' filter; per row of the tracks'
        bank its row there (-1: none).
        """
        if self.predictor is None:
            return self.bank, np.arange(len(self.bank), dtype=np.int64)
        return self.predictor, self._prow

    def _filters(self, a: int, b: int) -> Filters:
        """Per filter (the tracks', the long-arc predictor's), its bank and rows of a, b."""
        out = [(self.bank, a, b)]
        if self.predictor is not None:
            out.append((self.predictor, int(self._prow[a]), int(self._prow[b])))
        return out

    def _defer(self, rows: IntArray, track: IntArray, gated: Gated, station: str, st: int,
               t_scan: float, tt: Array, zz: Array, RR: Array) -> None:
        """Open forks on the scan's ambiguous pairs; fuse and score the open forks' H1.

        Called after the assignment (``track``: per detection its index in ``rows``), before
        the fusion: a new fork's shadows are the tracks' states before this scan.
        """
        deferral = self.deferral
        assert deferral is not None
        cfg = self.config
        scoring = self._scoring()
        srow = scoring[1]
        eligible = ((self.status[rows] == TrackStatus.CONFIRMED)
                    & (self._passes[rows] >= 1) & (self._passes[rows] <= cfg.defer_passes)
                    & (srow[rows] >= 0) & ~np.isin(rows, list(deferral.busy())))
        for i, k in ambiguous_pairs(track, gated.cost, gated.feasible, cfg.defer_margin,
                                    eligible):
            a, b = int(rows[i]), int(rows[k])
            deferral.open(a, b, t_scan, self._filters(a, b))
            self.counts[TrackEvent.DEFER_OPENED] += 1
        deferral.score(rows, track, scoring, station, st, t_scan, tt, zz, RR, self._scan,
                       self.bank.object_ids)

    def _decide(self, station: str, st: int, t_scan: float, tt: Array, zz: Array,
                RR: Array) -> None:
        """Decide the forks whose pass ended, on this scan (`deferral.PairDeferral.decide`).

        Each hypothesis is scored on the whole scan as `_tracks` would associate it
        (`_scan_cost`).
        """
        deferral = self.deferral
        assert deferral is not None
        rows = self._active_rows()
        self.relabels += deferral.decide(
            t_scan, self.status == TrackStatus.DELETED, self.config.defer_max_wait_s, rows,
            self.bank, st, tt, zz, RR, lambda: self._scan_cost(rows, st, tt, zz, RR),
            self._filters, self.counts)

    def _active_rows(self) -> IntArray:
        """Return the bank rows of the tracks associated with a scan (tracked, not deleted)."""
        n = len(self.bank)
        return np.flatnonzero(self.bank.tracking[:n] & (self.status[:n] != TrackStatus.DELETED))

    def _scan_cost(self, rows: IntArray, st: int, tt: Array, zz: Array, RR: Array) -> ScanCost:
        """Associate the scan with the tracks ``rows`` as `_tracks` does; return its cost.

        Returns the total over the tracks of ``min(d^2, gate) + ln det S`` on the detection
        the assignment gave each (the scores of `_gate_scan`: the long-arc predictor's,
        registered), ``gate + ln det S`` (S at the scan's first detection) for a track
        without one (as `deferral.pair_cost`), per detection its index in ``rows`` or
        `assignment.UNASSIGNED`, and per track the ``d^2`` of its detection (inf without
        one). Nothing is fused or counted.
        """
        bank = self.bank
        pred = predict_scan(bank.ekf, bank.x[rows], bank.P[rows], bank.t[rows], tt, st)
        gated = self._gate_scan(rows, pred, st, tt, zz, RR, count=False)
        track = assign(gated.cost, gated.feasible)
        with np.errstate(invalid="ignore"):
            logdet = gated.cost - gated.d2  # ln det S where computable, else nan
        miss = np.where(np.isfinite(logdet[:, 0]), logdet[:, 0], 0.0) + self._gate
        got = np.flatnonzero(track >= 0)
        i = track[got]
        d2 = np.full(rows.size, np.inf)
        d2[i] = gated.d2[i, got]
        hit = np.minimum(d2[i], self._gate) + logdet[i, got]
        return float(miss.sum() + (hit - miss[i]).sum()), track, d2

    def _gate_scan(self, rows: IntArray, pred: ScanPrediction, st: int, tt: Array,
                   zz: Array, RR: Array, count: bool = True) -> Gated:
        """Score the scan's pairs: `gating.gate_scan`, rescored by the long-arc predictor.

        ``pred`` is the tracks' filter's prediction of the bank rows ``rows``; only the
        tracks with a feasible pair are predicted again, by the long-arc predictor
        (`gating.gate_long_arc`; a track it does not hold, its IOD failed there, keeps the
        tracks' filter's score) and, with ``register_groups``, shifted along track by their
        group's `registration.register` shift (the tracks' filter's prediction when there is
        no long-arc predictor). ``count``: add the groups registered to `counts`.
        """
        wide = gate_scan(pred, zz, RR, self._gate)
        which = np.flatnonzero(wide.feasible.any(1))
        register_groups = self.config.register_groups and which.size > 1
        src = self.bank if self.predictor is None else self.predictor
        if self.predictor is None:
            if not register_groups:
                return wide
            pr = rows[which]
        else:
            pr = self._prow[rows[which]]
            which, pr = which[pr >= 0], pr[pr >= 0]
            keep = src.tracking[pr]
            which, pr = which[keep], pr[keep]
            if not which.size:
                return wide
        t0 = src.t[pr]
        fine = predict_scan(src.ekf, src.x[pr], src.P[pr], t0, tt, st)
        if register_groups and which.size > 1:
            assert fine.speed is not None
            sigma_s = pred.sigma_pos[:, which].max(0) / fine.speed.min(0)
            cfg = self.config
            shift = register(fine, zz, RR, wide.feasible[which], self._gate, sigma_s,
                             linked=linked_tracks(pred, fine, which, cfg.group_link_km,
                                                  cfg.group_link_speed_fraction))
            if count:
                self.counts[TrackEvent.GROUP_REGISTERED] += int(
                    np.unique(shift[shift != 0.0]).size)
            if np.any(shift != 0.0):  # the shifted tracks predicted again, exactly
                fine = predict_scan(src.ekf, src.x[pr], src.P[pr], t0 - shift, tt, st)
        return gate_long_arc(wide, gate_scan(fine, zz, RR, self._gate), which)

    def _close_passes(self, t_scan: float) -> None:
        """Count the passes that ended before `t_scan` without a detection."""
        ended = self._pass_open & (t_scan - self._last_expected > self.config.pass_gap_s)
        self._pass_open[ended] = False
        miss = ended & (self._pass_hits == 0)
        self._missed[ended & ~miss] = 0
        self._passes[ended & ~miss] += 1
        self._missed[miss] += 1
        gone = np.flatnonzero((self._missed >= self.config.delete_after_missed_passes)
                              & (self.status != TrackStatus.DELETED))
        self._delete(gone, TrackEvent.DELETED_MISSED_PASSES)

    def _expire(self, t_scan: float) -> None:
        """Drop the tracklets too old to extend; close the ended passes."""
        self._close_passes(t_scan)
        self.counts[TrackEvent.TRACKLET_EXPIRED] += self.tracklets.expire(t_scan)

    # --------------------------------------------------------------------------------------
    def _tracklets(self, station: str, st: int, free: IntArray, tt: Array, zz: Array,
                   RR: Array, ids: list[str], fate: NDArray[np.int8]) -> None:
        """Extend tracklets with the free detections, start new ones, start tracks."""
        if not free.size:
            return
        tl = self.tracklets
        r, C = detection_positions(self.bank.ekf, st, tt[free], zz[free], RR[free])
        raw: list[Detection] = [(float(tt[j]), zz[j], RR[j]) for j in free.tolist()]
        ext = tl.extend(st, r, C, tt[free], raw)
        self.counts[TrackEvent.TRACKLET_EXTENDED] += int(ext.extended.size)
        self.counts[TrackEvent.TRACKLET_STARTED] += ext.started
        for j, name in zip(free.tolist(), ext.names, strict=True):
            ids[j] = name
        fate[free[ext.extended]] = DetectionFate.TRACKLET
        done = tl.complete(self.iod_samples)
        for i in done.tolist():
            if not self._initiate(station, tl.ids[i]):
                fate[[j for j in free.tolist() if ids[j] == tl.ids[i]]] = (
                    DetectionFate.REFUSED)
        keep = np.ones(tl.length.size, dtype=bool)
        keep[done] = False
        tl.keep(keep)

    def _initiate(self, station: str, name: str) -> bool:
        """Hand a complete tracklet to the bank: whether its IOD started a track."""
        raw = self.tracklets.raw[name]
        res = self.bank.process([d[0] for d in raw], [name] * len(raw), [station] * len(raw),
                                [d[1] for d in raw], [d[2] for d in raw])
        ok = res.cause[-1] == "" and bool(self.bank.tracking[self.bank.rows[name]])
        if ok and self.predictor is not None:
            self.predictor.process([d[0] for d in raw], [name] * len(raw),
                                   [station] * len(raw), [d[1] for d in raw],
                                   [d[2] for d in raw])
            self._grow()
            self._prow[self.bank.rows[name]] = self.predictor.rows[name]
        self.counts[TrackEvent.TRACK_INITIATED if ok else TrackEvent.IOD_FAILED] += 1
        if not ok:
            self.bank.tracking[self.bank.rows[name]] = False
        return ok
