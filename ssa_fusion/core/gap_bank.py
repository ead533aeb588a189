"""Residual gap forecasts for a whole catalog, under a wall-time budget: `GapBank`.

One `gap_forecaster.GapForecaster` per object takes that object's estimates (those that fused a
real measurement). When an object has had no estimate for ``pass_break_s`` of sim time, its
newest estimate is a pass end: the object waits for a residual fit (`residual.
ResidualSurrogate`, about 0.3-0.6 s of one core each with a J2 placeholder). Fits run in
`GapBank.step` under a budget: on average at most ``fit_budget`` of the wall time that
passes between calls (a token bucket; one fit may overdraw it, the next waits until the
debt is repaid), the newest pass end first, since it has the most gap ahead of it. An object
whose gap ends (a new estimate) before its turn is not fitted (``skipped``): the node keeps
up with the stream by leaving gaps to the EKF's coasting, and counts every one. With
``fit_budget`` 0 there is no budget: every pass end found by a `step` is fitted in it, so
which gaps get a fit depends on sim time alone, never on the machine's speed or load (what
a lockstep run needs: it waits for the fits).

After its fit an object's forecast (the placeholder plus the learned residual, on the grid of
multiples of ``period_s``) is released epoch by epoch as sim time passes: `step` returns
those whose epoch lies at least ``hold_s`` before the clock (the filter's estimates reach
the bank later than the clock; a forecast for an epoch a real measurement covers would be
wrong), and `on_estimate` those due before the estimate that ends the gap. A forecast
published at or after the epoch of that estimate is counted as ``overtaken``.

Frames and units: GCRF km, km/s; times s (sim time, e.g. Unix s); ``fit_budget`` a fraction
of wall time (0: none).
"""

from __future__ import annotations

import math
import time
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .gap_forecaster import PLACEHOLDER_TRAJECTORY, GapForecaster
from .residual import LIVE_RESIDUAL, ResidualConfig
from .types import MotionModel
from .validation import MAX_OBJECTS

Array = NDArray[np.float64]

CATALOG_RESIDUAL = replace(LIVE_RESIDUAL, heldout_fits=1)
"""The residual setting of a catalog: the live filter's, each fit scored only at the end
of its own gap (`residual.ResidualConfig.heldout_fits`)."""


@dataclass(frozen=True)
class GapBankConfig:
    """Settings of a `GapBank`.

    Attributes
    ----------
    motion_model : MotionModel
        The filter's motion model ("kepler" or "j2", `gap_forecaster.PLACEHOLDER_TRAJECTORY`):
        the placeholder the residual is learned against.
    period_s : float
        Forecast grid, sim s: forecasts at the multiples of it in a gap.
    pass_break_s : float
        Sim s without an estimate after which the newest estimate ends a pass.
    hold_s : float
        Forecasts are released only for epochs at least this long (sim s) before the clock.
    fit_budget : float
        Fraction of wall time the fits may take on average (0 < fit_budget <= 1), or 0: no
        budget, every pass end is fitted at the step that finds it (deterministic).
    residual : ResidualConfig
        The residual model: the live filter's (`residual.LIVE_RESIDUAL`), each fit scored
        held-out only where its gap ends (``heldout_fits`` 1: one propagation per fit).
    """

    motion_model: MotionModel = MotionModel.J2
    period_s: float = 600.0
    pass_break_s: float = 600.0
    hold_s: float = 120.0
    fit_budget: float = 0.5
    residual: ResidualConfig = field(default_factory=lambda: CATALOG_RESIDUAL)

    def __post_init__(self) -> None:
        """Check the settings (ValueError naming the field)."""
        if self.motion_model not in PLACEHOLDER_TRAJECTORY:
            raise ValueError(f"motion_model must be {' or '.join(PLACEHOLDER_TRAJECTORY)}, "
                             f"got {self.motion_model!r}")
        object.__setattr__(self, "motion_model", MotionModel(self.motion_model))
        for name in ("period_s", "pass_break_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {v}")
        if not (math.isfinite(self.hold_s) and self.hold_s >= 0):
            raise ValueError(f"hold_s must be a finite number >= 0, got {self.hold_s}")
        if not 0 <= self.fit_budget <= 1:
            raise ValueError(f"fit_budget must be in [0, 1] (0: no budget), got "
                             f"{self.fit_budget}")


@dataclass(frozen=True)
class GapForecast:
    """One forecast of one object: epoch t (s), state x (6,) km, km/s GCRF, covariance P (6, 6)."""

    object_id: str
    t: float
    x: Array
    P: Array


class GapBank:
    """Gap forecasts of many objects (module docstring).

    Parameters
    ----------
    config : GapBankConfig
    wall : callable
        Wall clock, s (monotonic): what the budget is measured in.
    """

    def __init__(self, config: GapBankConfig,
                 wall: Callable[[], float] = time.perf_counter,
                 max_objects: int = MAX_OBJECTS) -> None:
        self.config = config
        self.wall = wall
        self.max_objects = int(max_objects)
        """The most objects the bank holds: an estimate of one more is refused (`admits`)."""
        self.counts: Counter[str] = Counter()
        """``fitted`` (a fit with a forecast), ``refused`` (too few anchors, or the fit
        refused), ``skipped`` (the gap ended before its turn), ``forecasts``, ``overtaken``."""
        self.fit_seconds = 0.0
        """Wall s spent fitting and scoring fits, in all (what the budget covers)."""
        self._rows: dict[str, int] = {}
        self._ids: list[str] = []
        self._gaps: list[GapForecaster] = []
        self._last = np.zeros(0)  # epoch of each object's newest estimate (s)
        self._fitted = np.zeros(0)  # the pass end each object was last fitted at (s)
        self._queued = np.zeros(0, dtype=bool)
        self._released = np.zeros(0)  # newest forecast epoch released per object (s)
        self._active: set[int] = set()  # rows with a forecast to release
        self._allowance = 0.0
        self._wall_last: float | None = None

    def __len__(self) -> int:
        """Return the number of objects heard of."""
        return len(self._ids)

    @property
    def object_ids(self) -> list[str]:
        """Return the ids of the objects heard of, in order of arrival."""
        return list(self._ids)

    @property
    def waiting(self) -> int:
        """Return the number of objects waiting for their fit."""
        return int(self._queued.sum())

    def admits(self, object_id: str) -> bool:
        """Return whether an estimate of `object_id` is taken: one held, or room for one more."""
        return object_id in self._rows or len(self._ids) < self.max_objects

    def _row(self, object_id: str) -> int:
        r = self._rows.get(object_id)
        if r is None:
            r = self._rows[object_id] = len(self._ids)
            self._ids.append(object_id)
            self._gaps.append(GapForecaster.for_model(
                self.config.motion_model, self.config.period_s, self.config.residual))
            self._gaps[r].pass_break_s = self.config.pass_break_s
            if r >= self._last.size:
                grow = max(self._last.size, 16)
                self._last = np.r_[self._last, np.full(grow, -math.inf)]
                self._fitted = np.r_[self._fitted, np.full(grow, -math.inf)]
                self._queued = np.r_[self._queued, np.zeros(grow, dtype=bool)]
                self._released = np.r_[self._released, np.full(grow, -math.inf)]
        return r

    def on_estimate(self, object_id: str, t: float, x: ArrayLike,
                    P: ArrayLike) -> list[GapForecast]:
        """Take an estimate of `object_id` that fused a real measurement.

        Epoch t (s), state x (6,) km, km/s GCRF, covariance P (6, 6). Return the forecasts
        of the gap it ends that were not yet released (their epochs before t). A second
        estimate at the epoch of the newest (another station's measurement fused after the
        first) replaces it. The caller checks `admits` first.
        """
        r = self._row(object_id)
        if not t >= self._last[r]:
            return []  # out of order: nothing new
        if t == self._last[r]:
            self._gaps[r].on_estimate(t, x, P)  # the better estimate of the same epoch
            return []
        out = list(self._release(r, math.nextafter(t, -math.inf))) if r in self._active else []
        if self._released[r] >= t:
            self.counts["overtaken"] += int(
                (self._released[r] - t) // self.config.period_s) + 1
        if self._queued[r]:
            self._queued[r] = False
            self.counts["skipped"] += 1
        self._active.discard(r)
        start = self.wall()
        self._gaps[r].on_estimate(t, x, P)  # a pass end becomes an anchor: scores its fit
        spent = self.wall() - start
        self.fit_seconds += spent
        self._allowance -= spent
        self._last[r] = t
        return out

    def step(self, now: float) -> list[GapForecast]:
        """Queue, fit and release at sim time `now` (s).

        Queue the objects whose pass just ended, fit as many as the budget allows (newest
        pass end first), and return every forecast now due.
        """
        c = self.config
        n = len(self._ids)
        last = self._last[:n]
        new = (now - last >= c.pass_break_s) & (self._fitted[:n] != last) & ~self._queued[:n]
        self._queued[:n] |= new
        wall = self.wall()
        if self._wall_last is not None:
            self._allowance = min(self._allowance + c.fit_budget * (wall - self._wall_last),
                                  c.fit_budget)  # no more than one wall second saved up
        self._wall_last = wall
        while (self._allowance > 0.0 or not c.fit_budget) and self._queued[:n].any():
            r = int(np.flatnonzero(self._queued[:n])[np.argmax(last[self._queued[:n]])])
            self._queued[r] = False
            spent = self._fit(r)  # the fit's own wall time accrues at the next step
            self.fit_seconds += spent
            self._allowance -= spent
        out: list[GapForecast] = []
        for r in sorted(self._active):
            out.extend(self._release(r, now - c.hold_s))
        return out

    def _fit(self, r: int) -> float:
        """Fit object `r` at its pass end; return the wall s it took."""
        t0 = self.wall()
        g = self._gaps[r]
        end = float(self._last[r])
        self._fitted[r] = end
        first = self.config.period_s * (math.floor((end + g.pass_break_s)
                                                   / self.config.period_s) + 1)
        g.forecast(first)  # the forecaster anchors, fits and tabulates here
        if g.table:
            self.counts["fitted"] += 1
            self._released[r] = end
            self._active.add(r)
        else:
            self.counts["refused"] += 1
        return self.wall() - t0

    def _release(self, r: int, until: float) -> Iterator[GapForecast]:
        """Yield object `r`'s tabulated forecasts after the last released, up to `until`."""
        g = self._gaps[r]
        start = self._last[r] + g.pass_break_s
        for t in [t for t in g.table if self._released[r] < t <= until]:
            x, P = g.table.pop(t)
            self._released[r] = t
            if t >= start:
                self.counts["forecasts"] += 1
                yield GapForecast(self._ids[r], t, x, P)
        if not g.table:
            self._active.discard(r)
