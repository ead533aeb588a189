"""Gap forecasts for a whole catalog, under a wall-time budget: `GapBank`.

Each object's gaps are forecast as its `GapFill` says (``gap_forecast`` of the config, or
`GapBank.choose` per object):

* `GapFill.RESIDUAL`: one `gap_forecaster.GapForecaster` per object takes that object's
  estimates (those that fused a real measurement) and learns the residual of the motion
  model at its pass ends (`residual.ResidualSurrogate`; with a J2 placeholder about 10 ms
  of one core per fit made on a catalog of every regime, the refused ones included:
  ``bench/bench_gap_fits.py``); until its pass ends span a day (`residual.ResidualConfig`
  ``min_span_s``, ``min_anchors``), or when its fit is refused, a gap gets the physics-only
  forecast from its pass end instead (`GapBankConfig.physics`, `residual.PHYSICS_RESIDUAL`:
  from the object's first pass end on), counted as ``fitted_physics``;
* `GapFill.BATCH_FIT`: the object's real measurements (`on_measurements`) of its last
  passes are kept (`measurement_windows.MeasurementWindows`, arrays) and fitted by batch
  least squares from its newest estimate by `batch_gap.BatchGapForecaster` (the
  single-object filter's options and table of its prediction on the grid up to a day after
  the pass), over the last `GapBankConfig.fit_passes` passes only (`last_passes_forecaster`:
  not the single-object filter's passes of the last 24 h).

When an object has had no estimate for ``pass_break_s`` of sim time, its newest estimate is
a pass end: the object waits for its fit, whichever it is. Fits run in
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
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.rows import MeasurementRows
from ssa_fusion.core.base.types import MotionModel, Source
from ssa_fusion.core.gaps.batch_gap import GAP_FIT_PASSES, BatchGapForecaster
from ssa_fusion.core.gaps.forecaster import PLACEHOLDER_TRAJECTORY, GapForecaster
from ssa_fusion.core.gaps.measurement_windows import MAX_WINDOW_ROWS, MeasurementWindows
from ssa_fusion.core.gaps.publisher import GapFill
from ssa_fusion.core.gaps.residual import LIVE_RESIDUAL, PHYSICS_RESIDUAL, ResidualConfig
from ssa_fusion.core.measure.measurement import MeasurementModel
from ssa_fusion.core.measure.pass_windows import PASS_BREAK_S
from ssa_fusion.core.measure.validation import MAX_OBJECTS

Array = NDArray[np.float64]

CATALOG_RESIDUAL = replace(LIVE_RESIDUAL, heldout_fits=1)
"""The residual setting of a catalog: the live filter's, each fit scored only at the end
of its own gap (`residual.ResidualConfig.heldout_fits`)."""


GAP_FORECASTS = (GapFill.RESIDUAL, GapFill.BATCH_FIT)
"""The gap forecasts a catalog's objects choose from (a catalog_surrogate cannot restart the
catalog_filter's EKF: no `GapFill.BATCH_INIT`; no forecast is no surrogate)."""


def last_passes_forecaster(model: MeasurementModel, period_s: float, clock_unix0: float = 0.0,
                           passes: int = GAP_FIT_PASSES,
                           pass_break_s: float = PASS_BREAK_S) -> BatchGapForecaster:
    """Return a `batch_gap.BatchGapForecaster` whose window is the last `passes` passes only.

    A catalog's window: each object keeps only its last passes (`MeasurementWindows`), not
    the single-object filter's passes of the last `batch_gap.GAP_FIT_SPAN_H` hours, which
    would hold a day of a network's measurements (up to `batch_gap.GAP_FIT_MAX_MEASUREMENTS`
    rows) for each of tens of thousands of objects. Its covariance is the fit's own (no
    calibration on the last passes, `batch_gap.BatchGapForecaster.calibrate`: a catalog
    object's forecaster is made anew from its window, without the history it needs).
    """
    return BatchGapForecaster(model, period_s, clock_unix0=clock_unix0, passes=passes,
                              span_h=0.0, max_measurements=None, span_h_angles=0.0,
                              pass_break_s=pass_break_s, calibrate=False)

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
    physics : ResidualConfig or None
        The physics-only fit of a gap the residual has no fit for
        (`residual.PHYSICS_RESIDUAL`; None: such a gap gets no forecast).
    gap_forecast : GapFill
        Every object's gap forecast unless chosen per object (`GAP_FORECASTS`).
    fit_passes : int
        Passes of real measurements a batch fit spans (`batch_gap.GAP_FIT_PASSES`).
    max_window_rows : int
        Most measurements an object's batch-fit window keeps.
    """

    motion_model: MotionModel = MotionModel.J2
    period_s: float = 600.0
    pass_break_s: float = 600.0
    hold_s: float = 120.0
    fit_budget: float = 0.5
    residual: ResidualConfig = field(default_factory=lambda: CATALOG_RESIDUAL)
    physics: ResidualConfig | None = field(default_factory=lambda: PHYSICS_RESIDUAL)
    gap_forecast: GapFill = GapFill.RESIDUAL
    fit_passes: int = GAP_FIT_PASSES
    max_window_rows: int = MAX_WINDOW_ROWS

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
        if self.gap_forecast not in GAP_FORECASTS:
            raise ValueError(f"gap_forecast must be {' or '.join(GAP_FORECASTS)}, got "
                             f"{self.gap_forecast!r}")
        object.__setattr__(self, "gap_forecast", GapFill(self.gap_forecast))
        if self.fit_passes < 1 or self.max_window_rows < 1:
            raise ValueError(f"fit_passes and max_window_rows must be >= 1, got "
                             f"{self.fit_passes}, {self.max_window_rows}")
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
    physics: bool = False
    """Of the physics-only fit (`GapBankConfig.physics`), not the learned residual's."""


class GapBank:
    """Gap forecasts of many objects (module docstring).

    Parameters
    ----------
    config : GapBankConfig
    wall : callable
        Wall clock, s (monotonic): what the budget is measured in.
    max_objects : int
        The most objects the bank holds.
    model : MeasurementModel, optional
        The measurements' model (e.g. the catalog's radars, `measurement.StationModels`):
        needed by objects with `GapFill.BATCH_FIT`.
    clock_unix0 : float
        Unix time (s) of t = 0 of the sim clock (0: sim time is Unix s).
    """

    def __init__(self, config: GapBankConfig,
                 wall: Callable[[], float] = time.perf_counter,
                 max_objects: int = MAX_OBJECTS, model: MeasurementModel | None = None,
                 clock_unix0: float = 0.0) -> None:
        if config.gap_forecast == GapFill.BATCH_FIT and model is None:
            raise ValueError("a batch fit of the gaps needs the measurements' model")
        self.config = config
        self.wall = wall
        self.max_objects = int(max_objects)
        """The most objects the bank holds: an estimate of one more is refused (`admits`)."""
        self.model = model
        self.clock_unix0 = float(clock_unix0)
        self.counts: Counter[str] = Counter()
        """``fitted`` (a fit with a forecast; ``fitted_batch_fit`` those of a batch fit,
        ``fitted_physics`` those of the physics-only fit, `GapBankConfig.physics`),
        ``refused`` (too few anchors, or the fit refused or failed), ``skipped`` (the gap
        ended before its turn), ``cut`` (queued when the node stopped: `step`),
        ``forecasts``, ``overtaken``, ``measurements`` (kept in a batch-fit window)."""
        self.fit_seconds = 0.0
        """Wall s spent fitting and scoring fits, in all (what the budget covers)."""
        self.windows = MeasurementWindows(config.fit_passes, config.pass_break_s,
                                          config.max_window_rows)
        """The batch-fit objects' measurements of their last passes."""
        self._rows: dict[str, int] = {}
        self._ids: list[str] = []
        self._gaps: list[GapForecaster | None] = []  # residual objects' forecasters
        self._tables: dict[int, dict[float, tuple[Array, Array]]] = {}  # batch fits' tables
        self._batch = np.zeros(0, dtype=bool)  # the object's gaps are batch-fitted
        self._x = np.zeros((0, 6))  # each object's newest estimate (km, km/s GCRF)
        self._last = np.zeros(0)  # epoch of each object's newest estimate (s)
        self._fitted = np.zeros(0)  # the pass end each object was last fitted at (s)
        self._queued = np.zeros(0, dtype=bool)
        self._released = np.zeros(0)  # newest forecast epoch released per object (s)
        self._active: set[int] = set()  # rows with a forecast to release
        self._pending: list[MeasurementRows] = []  # measurements waiting for the clock
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

    def gap_forecast(self, object_id: str) -> GapFill:
        """Return how the gaps of `object_id` are forecast (the config's if not heard of)."""
        r = self._rows.get(object_id)
        if r is None:
            return self.config.gap_forecast
        return GapFill.BATCH_FIT if self._batch[r] else GapFill.RESIDUAL

    def choose(self, object_id: str, fill: GapFill) -> None:
        """Forecast the gaps of `object_id` with `fill` (one of `GAP_FORECASTS`) from now on.

        What the other forecast learnt of it (anchors, or a window) is forgotten; a forecast
        tabulated already is still released. ValueError for a fill the bank does not make,
        a batch fit without the measurements' model, or no room for the object.
        """
        fill = GapFill(fill)
        if fill not in GAP_FORECASTS:
            raise ValueError(f"gap forecast must be {' or '.join(GAP_FORECASTS)}, got {fill!r}")
        if fill == GapFill.BATCH_FIT and self.model is None:
            raise ValueError("a batch fit of the gaps needs the measurements' model")
        if not self.admits(object_id):
            raise ValueError(f"object {object_id!r}: the bank holds max_objects already")
        r = self._row(object_id)
        batch = fill == GapFill.BATCH_FIT
        if batch == self._batch[r]:
            return
        self._batch[r] = batch
        if batch:
            self._gaps[r] = None
        else:
            self.windows.forget(r)
            self._gaps[r] = self._forecaster()

    def _forecaster(self) -> GapForecaster:
        c = self.config
        g = GapForecaster.for_model(c.motion_model, c.period_s, c.residual, c.physics)
        g.pass_break_s = c.pass_break_s
        return g

    def _row(self, object_id: str) -> int:
        r = self._rows.get(object_id)
        if r is None:
            r = self._rows[object_id] = len(self._ids)
            self._ids.append(object_id)
            batch = self.config.gap_forecast == GapFill.BATCH_FIT
            self._gaps.append(None if batch else self._forecaster())
            if r >= self._last.size:
                grow = max(self._last.size, 16)
                self._last = np.r_[self._last, np.full(grow, -math.inf)]
                self._fitted = np.r_[self._fitted, np.full(grow, -math.inf)]
                self._queued = np.r_[self._queued, np.zeros(grow, dtype=bool)]
                self._released = np.r_[self._released, np.full(grow, -math.inf)]
                self._batch = np.r_[self._batch, np.zeros(grow, dtype=bool)]
                self._x = np.concatenate([self._x, np.zeros((grow, 6))])
                self.windows.grow(self._last.size)
            self._batch[r] = batch
        return r

    def on_measurements(self, rows: MeasurementRows) -> int:
        """Take real measurements (e.g. a catalog's batch); return how many are kept.

        Those of a batch-fit object (objects not yet heard of are, when the config's
        forecast is `GapFill.BATCH_FIT` and there is room) wait until `step` reaches their
        epoch, then go to its window in epoch order (a stable sort); others, and forecasts,
        are ignored. Waiting for the clock keeps a pass that starts ahead of it (a lockstep
        step's measurements run ahead of its clock) out of the fit of the gap before it.
        """
        if not len(rows):
            return 0
        default = self.config.gap_forecast == GapFill.BATCH_FIT
        sensor = rows.source == Source.SENSOR if rows.source.size else np.ones(len(rows), bool)
        keep = np.zeros(len(rows), bool)
        for i in np.flatnonzero(sensor).tolist():
            oid = rows.object_id[i]
            r = self._rows.get(oid)
            if r is None and default and self.admits(oid):
                r = self._row(oid)
            keep[i] = r is not None and bool(self._batch[r])
        if keep.any():
            self._pending.append(rows.take(np.flatnonzero(keep)))
        return int(keep.sum())

    def _admit_measurements(self, now: float) -> None:
        """Move the measurements waiting for the clock up to `now` (s) into the windows."""
        if not self._pending:
            return
        rows = MeasurementRows.concat(self._pending)
        due = rows.t <= now
        self._pending = [rows.take(np.flatnonzero(~due))] if not due.all() else []
        kept = 0
        for i in np.flatnonzero(due)[np.argsort(rows.t[due], kind="stable")].tolist():
            r = self._rows.get(rows.object_id[i])
            if r is not None and self._batch[r]:
                kept += self.windows.add(r, float(rows.t[i]), rows.z[i], rows.R[i],
                                         int(rows.kind[i]), rows.frame_id[i])
        self.counts["measurements"] += kept

    def admitted(self, object_ids: Sequence[str]) -> NDArray[np.bool_]:
        """Return which of `object_ids` (rows in order) `admits`, as they would come one by one.

        Those held, and new ones in order of first appearance while there is room.
        """
        if not len(object_ids):
            return np.zeros(0, dtype=bool)
        uniq, first, inverse = np.unique(np.asarray(object_ids, dtype=object),
                                         return_index=True, return_inverse=True)
        held = np.fromiter((u in self._rows for u in uniq.tolist()), bool, uniq.size)
        new = np.flatnonzero(~held)
        room = max(self.max_objects - len(self._ids), 0)
        ok = held.copy()
        ok[new[np.argsort(first[new], kind="stable")[:room]]] = True
        out: NDArray[np.bool_] = ok[inverse.ravel()]
        return out

    def on_estimates(self, object_ids: Sequence[str], t: NDArray[np.float64],
                     x: NDArray[np.float64], P: NDArray[np.float64]) -> list[GapForecast]:
        """Take a batch of estimates (rows in order, as `on_estimate` takes them one by one).

        Epochs t (M,) s, states x (M, 6) km, km/s GCRF, covariances P (M, 6, 6). Only the rows
        that change what the bank ends with are handed to `on_estimate`: of each object in
        the batch its first and its last, those `pass_break_s` or more from the one before
        or after (a gap's end, a pass end) and those out of epoch order; the rows between
        are each replaced by the next (the newest estimate of a pass is what is kept). Return
        the forecasts released. The caller checks `admitted` first.
        """
        if not len(object_ids):
            return []
        codes = np.unique(np.asarray(object_ids, dtype=object), return_inverse=True)[1].ravel()
        order = np.lexsort((np.arange(codes.size), codes))
        c, tt = codes[order], np.asarray(t, dtype=float)[order]
        same = c[1:] == c[:-1]
        gap = np.where(same, np.diff(tt), np.inf)
        odd = ~((gap >= 0.0) & (gap < self.config.pass_break_s))  # breaks, disorder, NaN
        need = np.ones(codes.size, dtype=bool)
        need[1:-1] = odd[:-1] | odd[1:]
        keep = np.sort(order[need])
        out: list[GapForecast] = []
        for i in keep.tolist():
            out += self.on_estimate(object_ids[i], float(t[i]), x[i], P[i])
        return out

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
        g = self._gaps[r]
        if t == self._last[r]:
            self._x[r] = x
            if g is not None:
                g.on_estimate(t, x, P)  # the better estimate of the same epoch
            return []
        out = list(self._release(r, math.nextafter(t, -math.inf))) if r in self._active else []
        if self._released[r] >= t:
            self.counts["overtaken"] += int(
                (self._released[r] - t) // self.config.period_s) + 1
        if self._queued[r]:
            self._queued[r] = False
            self.counts["skipped"] += 1
        self._active.discard(r)
        self._tables.pop(r, None)
        self._x[r] = x
        if g is not None:
            start = self.wall()
            g.on_estimate(t, x, P)  # a pass end becomes an anchor: scores its fit
            spent = self.wall() - start
            self.fit_seconds += spent
            self._allowance -= spent
        self._last[r] = t
        return out

    def step(self, now: float, stop: Callable[[], bool] | None = None) -> list[GapForecast]:
        """Queue, fit and release at sim time `now` (s).

        Move the measurements up to `now` into the windows, queue the objects whose pass
        just ended, fit as many as the budget allows (newest pass end first), and return
        every forecast now due. Once `stop()` is True (the node is stopping) the fits still
        queued are cut: counted as ``cut``, their gaps left to the filter's coasting, never
        queued again.
        """
        c = self.config
        self._admit_measurements(now)
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
            if stop is not None and stop():
                cut = np.flatnonzero(self._queued[:n])
                self.counts["cut"] += cut.size
                self._queued[cut] = False
                self._fitted[cut] = last[cut]
                break
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
        c = self.config
        end = float(self._last[r])
        self._fitted[r] = end
        first = c.period_s * (math.floor((end + c.pass_break_s) / c.period_s) + 1)
        g = self._gaps[r]
        if g is not None:
            g.forecast(first)  # the forecaster anchors, fits and tabulates here
            table = g.table
        else:
            table = self._tables[r] = self.batch_fit(r, first)
        if table:
            self.counts["fitted"] += 1
            if g is None:
                self.counts["fitted_batch_fit"] += 1
            elif g.physics_fit:
                self.counts["fitted_physics"] += 1
            self._released[r] = end
            self._active.add(r)
        else:
            self.counts["refused"] += 1
        return self.wall() - t0

    def batch_fit(self, r: int, first: float) -> dict[float, tuple[Array, Array]]:
        """Return object `r`'s batch fit tabulated on the grid, from its newest estimate.

        `batch_gap.BatchGapForecaster` given the object's window up to its newest estimate
        (a measurement after it was not fused) and that estimate, asked for its forecast
        at `first` (s), the first grid epoch of the gap: the fit's states and covariances at
        the grid epochs after the pass end ({} when the fit failed).
        """
        assert self.model is not None
        end = float(self._last[r])
        f = last_passes_forecaster(self.model, self.config.period_s,
                                   clock_unix0=self.clock_unix0, passes=self.config.fit_passes,
                                   pass_break_s=self.config.pass_break_s)
        f.window = [m for m in self.windows.window(r) if m.t <= end]
        f.last = (end, self._x[r].copy())
        try:  # one object's failed fit leaves its gap to the filter's coasting
            f.forecast(first)
        except (ValueError, ArithmeticError, np.linalg.LinAlgError):
            return {}
        return f.table

    def _table(self, r: int) -> dict[float, tuple[Array, Array]]:
        g = self._gaps[r]
        return g.table if g is not None else self._tables.get(r, {})

    def _release(self, r: int, until: float) -> Iterator[GapForecast]:
        """Yield object `r`'s tabulated forecasts after the last released, up to `until`.

        A residual forecaster tabulates up to `until` first (`GapForecaster.extend`; its
        wall time counts as fitting, `fit_seconds`).
        """
        g = self._gaps[r]
        if g is not None and g.pending:
            start = self.wall()
            g.extend(until)  # tabulating the fit's forecast is fitting: the budget's
            spent = self.wall() - start
            self.fit_seconds += spent
            self._allowance -= spent
        table = self._table(r)
        start = self._last[r] + self.config.pass_break_s
        physics = g is not None and g.physics_fit
        for t in [t for t in table if self._released[r] < t <= until]:
            x, P = table.pop(t)
            self._released[r] = t
            if t >= start:
                self.counts["forecasts"] += 1
                yield GapForecast(self._ids[r], t, x, P, physics)
        if not table and not (g is not None and g.pending):
            self._active.discard(r)
            self._tables.pop(r, None)
