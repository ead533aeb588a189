"""Watching a live catalog for close approaches: `ConjunctionWatch`.

A catalog's estimates arrive in batches (each row an object's state and covariance at its
own epoch). `ConjunctionWatch.update` keeps each object's newest estimate and marks it
changed; `ConjunctionWatch.rescreen` screens the changed objects against every object known
(`screening.screen` with them as primaries, the newest estimates flown with the filter's
motion model) over ``[now, now + horizon_s]``, and replaces every approach that involved
them: an approach is always the one of the newest estimates of both objects. The flown
trajectories are kept between re-screenings (`trajectory_store.TrajectoryStore`, nodes on a
fixed grid of epochs): an object whose estimate did not change is only carried on to the
window's new end, not flown again. Objects whose radial band (osculating perigee to apogee of the
estimate, widened by ``band_pad_km`` for what the window's perturbations move it) meets no
changed object's are not flown at all.

Each approach carries both covariances at TCA (the estimates' carried by the state
transition matrix) and its 2D Pc (Foster, hard-body radius ``hbr_km``). Units: epochs Unix
s (UTC), km, km/s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.constants import R_EARTH
from ssa_fusion.core.base.types import MotionModel
from ssa_fusion.core.conjunction.apsides import meets_any, osculating_apsides
from ssa_fusion.core.conjunction.close_approach import CloseApproaches
from ssa_fusion.core.conjunction.screening import ScreeningConfig, screen
from ssa_fusion.core.conjunction.trajectory_store import TrajectoryStore

__all__ = ["ConjunctionWatch", "Rescreening", "WatchConfig", "WatchUpdate"]

Array = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class WatchConfig:
    """How a live catalog is watched (`ConjunctionWatch`).

    Attributes
    ----------
    screening : ScreeningConfig
        Screening distance and sampling.
    horizon_s : float
        Length of the window screened after the newest estimate, s.
    hbr_km : float
        Combined hard-body radius of the Pc, km.
    model : MotionModel
        The estimates' motion model (`propagation.INTEGRATED_MODELS`).
    band_pad_km : float
        Widening of each estimate's osculating radial band, km.
    pc_refine_below : float
        Pc below which the 2D Pc keeps the Gauss-Legendre value where its two rules
        disagree (`pc2d.log10_pc_circle`'s ``refine_below_log10``: no ~10 ms adaptive
        integration for each of the thousands of approaches with a Pc of 1e-30 or 1e-300;
        their values are the fine rule's, the decisions at 1e-4 to 1e-7 unaffected).
    min_perigee_km : float
        Estimates whose osculating perigee altitude is below this are not flown (their orbit
        meets the atmosphere's dense layers or the Earth: they re-enter within a revolution,
        and flown through the Earth two-body + J2 accelerations grow without bound), km.
    max_step_s : float
        Longest DOP853 step of the flown trajectories, s (150 s: < 1 µm a day in LEO apart
        from 60 s steps).
    covariance_step_s : float
        Longest DOP853 step of the state transition matrices that carry the covariances to
        TCA, s (300 s: 1e-7 relative apart from 60 s steps over a day in LEO).
    """

    screening: ScreeningConfig = field(default_factory=lambda: ScreeningConfig(distance_km=5.0))
    horizon_s: float = 86400.0
    hbr_km: float = 0.02
    model: MotionModel = MotionModel.J2
    band_pad_km: float = 50.0
    pc_refine_below: float = 1e-15
    min_perigee_km: float = 100.0
    max_step_s: float = 150.0
    covariance_step_s: float = 300.0


@dataclass(frozen=True)
class WatchUpdate:
    """What one re-screening found.

    Attributes
    ----------
    screened : list of str
        The objects re-screened: every approach involving one of them is replaced by
        ``approaches`` (none left: they have none in the window).
    approaches : CloseApproaches
        Their approaches in the window, by TCA (ids in ``approaches.object_ids``).
    log10_pc : ndarray (M,)
        The 2D Pc of each, as its log10.
    window : (float, float)
        The window screened, Unix s.
    distance_km : float
        The screening distance, km.
    hbr_km : float
        The combined hard-body radius of the Pc, km.
    """

    screened: list[str]
    approaches: CloseApproaches
    log10_pc: Array
    window: tuple[float, float]
    distance_km: float
    hbr_km: float


class ConjunctionWatch:
    """The newest estimate of every object, and the approaches they make (module docstring)."""

    def __init__(self, config: WatchConfig | None = None) -> None:
        """Watch with ``config`` (defaults: 5 km, one day ahead, 20 m, J2)."""
        self.config = config or WatchConfig()
        self._index: dict[str, int] = {}
        self._t = np.zeros(0)
        self._x = np.zeros((0, 6))
        self._p = np.zeros((0, 6, 6))
        self._changed: set[int] = set()
        self._store = TrajectoryStore(self.config.model, self.config.screening.node_step_s,
                                      self.config.max_step_s, self.config.covariance_step_s)

    @property
    def objects(self) -> int:
        """Number of objects with an estimate."""
        return len(self._index)

    @property
    def pending(self) -> int:
        """Number of objects changed since the last re-screening."""
        return len(self._changed)

    def _grow(self, n: int) -> None:
        """Make room for ``n`` objects."""
        if n > self._t.size:
            size = max(n, 2 * self._t.size, 64)
            self._t = np.resize(self._t, size)
            self._x = np.resize(self._x, (size, 6))
            self._p = np.resize(self._p, (size, 6, 6))

    def update(self, object_ids: list[str], t: ArrayLike, x: ArrayLike, p: ArrayLike) -> int:
        """Keep the newest estimate of each object; return how many changed.

        ``t`` (M,) Unix s, ``x`` (M, 6) GCRF km, km/s, ``p`` (M, 6, 6) km², km²/s, km²/s².
        An estimate older than the one held, not finite, or whose perigee is too low
        (`too_low`) is ignored.
        """
        tt = np.asarray(t, dtype=float).reshape(-1)
        xx = np.asarray(x, dtype=float).reshape(-1, 6)
        pp = np.asarray(p, dtype=float).reshape(-1, 6, 6)
        ok = np.isfinite(tt) & np.isfinite(xx).all(axis=1) & np.isfinite(pp).all(axis=(1, 2))
        ok &= ~np.isfinite(self.too_low(xx))
        changed = 0
        for k, oid in enumerate(object_ids):
            if not ok[k]:
                continue
            i = self._index.get(oid)
            if i is None:
                i = self._index[oid] = len(self._index)
                self._grow(i + 1)
            elif tt[k] <= self._t[i]:
                continue
            self._t[i], self._x[i], self._p[i] = tt[k], xx[k], pp[k]
            self._changed.add(i)
            changed += 1
        return changed

    def too_low(self, x: ArrayLike) -> Array:
        """Return the perigee altitude (km) of states ``x`` (M, 6) too low to fly, else NaN.

        Below ``config.min_perigee_km`` (`WatchConfig`); non-finite states are NaN.
        """
        with np.errstate(invalid="ignore"):
            rp, _, _ = osculating_apsides(np.asarray(x, dtype=float).reshape(-1, 6))
            alt = rp - R_EARTH
            out: Array = np.where(alt < self.config.min_perigee_km, alt, np.nan)
        return out

    def _near(self, primary: BoolArray) -> BoolArray:
        """Return the objects whose padded radial band meets some primary's (N,)."""
        rp, ra, _ = osculating_apsides(self._x[:self.objects])
        pad = self.config.band_pad_km
        near: BoolArray = meets_any(rp - pad, ra + pad, primary,
                                    self.config.screening.distance_km) | primary
        return near

    def snapshot(self, now: float | None = None) -> Rescreening:
        """Take the re-screening of the changed objects over ``[now, now + horizon_s]``.

        ``now`` defaults to the newest estimate's epoch. The changed set is emptied; the
        estimates it needs are copied (`Rescreening.run` may go on in another thread while
        this watch takes new ones).
        """
        n = self.objects
        ids = list(self._index)
        newest = float(np.max(self._t[:n])) if n else 0.0
        start = newest if now is None else float(now)
        changed = np.zeros(n, dtype=np.bool_)
        changed[list(self._changed)] = True
        self._changed.clear()
        use = np.flatnonzero(self._near(changed)) if changed.any() else np.zeros(0, np.int64)
        # screened in the order of their ids, not of their first estimates' arrival (two
        # filter shards' batches interleave as DDS delivers them): the same approaches,
        # with the same primaries, whatever the order
        use = use[np.argsort(np.array([ids[k] for k in use], dtype=object), kind="stable")]
        return Rescreening([ids[k] for k in use], self._x[use], self._t[use], self._p[use],
                           changed[use], (start, start + self.config.horizon_s), self.config,
                           use, self._store)

    def rescreen(self, now: float | None = None) -> WatchUpdate:
        """Screen the changed objects against all (`snapshot`, then `Rescreening.run`)."""
        return self.snapshot(now).run()


@dataclass(frozen=True)
class Rescreening:
    """One re-screening, with copies of the estimates it needs (`ConjunctionWatch.snapshot`).

    Attributes
    ----------
    ids : list of str
        The objects flown: the changed ones and those whose band meets theirs.
    x, t, p : ndarray
        Their estimates: states (M, 6), epochs (M,), covariances (M, 6, 6).
    changed : ndarray (M,) of bool
        The changed ones (the primaries).
    window : (float, float)
        Unix s.
    config : WatchConfig
    rows : ndarray (M,) of int
        Their rows in ``store``.
    store : TrajectoryStore
        The watch's trajectories: this re-screening's while it runs (the watch starts the
        next one after it ended).
    """

    ids: list[str]
    x: Array
    t: Array
    p: Array
    changed: BoolArray
    window: tuple[float, float]
    config: WatchConfig
    rows: NDArray[np.int64]
    store: TrajectoryStore

    def run(self) -> WatchUpdate:
        """Screen (`screening.screen`); return the approaches with their Pc."""
        d, hbr = self.config.screening.distance_km, self.config.hbr_km
        screened = [self.ids[k] for k in np.flatnonzero(self.changed)]
        if not screened:
            return WatchUpdate([], CloseApproaches.empty(self.ids, covariances=True),
                               np.zeros(0), self.window, d, hbr)
        store = self.store
        start = math.floor(self.window[0] / store.step_s) * store.step_s  # a node
        store.keep_from(int(store.node(start)) - 1)
        store.set_estimates(self.rows[self.changed], self.x[self.changed],
                            self.t[self.changed])
        eph = store.view(self.rows, self.p)
        found = screen(eph, start, self.window[1], self.config.screening, primaries=self.changed)
        found = replace(found.take(found.tca >= self.window[0]), object_ids=tuple(self.ids))
        log10_pc = found.log10_pc(hbr, math.log10(self.config.pc_refine_below))
        return WatchUpdate(screened, found, log10_pc, self.window, d, hbr)
