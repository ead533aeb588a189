"""What a filter publishes: the estimates of what it fuses and, through a gap, predictions.

The one publication policy of the single-object filter, shared by the filter node (live)
and the offline replay, so that both publish the same estimates for the same input:

* every estimate the tracker makes is published (an update, and the estimates it fuses
  again after a late measurement), tagged with the tracker's object id, else that of the
  last measurement it fused;
* when nothing was fused for `period_s` of sim time, a prediction (update source NONE,
  covariance growing) is published at every multiple of `period_s` through the gap: on the
  truth's grid when the two cadences agree, each predicted on from the previous one, so a
  gap of hours costs one short propagation per prediction. The caller's clock drives them
  (`advance`); before a real measurement is fused, every prediction due before its epoch
  is published first (`measurement`), so the grid through a gap is complete however fast
  sim time runs, and what is published does not depend on how often the clock is read;
* with a gap forecaster (`GapForecast`), a prediction epoch it covers is published as its
  forecast instead (update source FORECAST): the motion model plus its residual learned
  from past pass ends (`gap_forecaster.GapForecaster`), or a batch least-squares fit of
  the last passes (`batch_gap.BatchGapForecaster`, which takes the real measurements the
  filter fused as well). The EKF itself coasts on: the next real measurement updates its
  own prediction;
* with ``batch_init`` (`GapFill.BATCH_INIT`), the batch fit's prediction also becomes the
  EKF's prior at the first real measurement of the next pass (more than the forecaster's
  ``pass_break_s`` after the last one fused): the EKF starts its sequential update there
  from the fit's state and realistic covariance instead of its own coasted ones
  (`Tracker.restart_from`), once per fit and from a fit of a full window of passes;
  otherwise (no fit yet, a failed one, or one of fewer passes) it goes on from its own;
* with ``fit_residual`` (`GapFill.FIT_RESIDUAL`), as ``batch_init``, with the fit's
  prediction corrected by the residual surrogate learnt against the fit
  (`fit_residual.FitResidualForecaster`).

Predictions never change the tracker (only a pass's prior, above); at most `limit` are
published per call, and the earliest are skipped when more than ten times that many are due
at once (a clock that jumped far ahead), as `tracker.prediction_epochs` says.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.types import Measurement, Source, StateEstimate, UpdateSource
from ssa_fusion.core.earth.timescales import DAY_S, UNIX_EPOCH_JD
from ssa_fusion.core.filter.tracker import Outcome, Tracker, prediction_epochs
from ssa_fusion.core.gaps.batch_gap import BatchGapForecaster
from ssa_fusion.core.gaps.estimator import EstimatorConfig, measurement_model
from ssa_fusion.core.gaps.fit_residual import FitResidualForecaster
from ssa_fusion.core.gaps.forecaster import GapForecaster
from ssa_fusion.core.od.batch_ls import BatchOptions

Array = NDArray[np.float64]

PREDICTIONS_PER_CALL = 100
"""Most predictions `GapPublisher.advance` publishes per call (a backlog over later calls)."""
PREDICTIONS_BEFORE_MEASUREMENT = 10 * PREDICTIONS_PER_CALL
"""Most predictions published before one real measurement."""


class GapFill(enum.StrEnum):
    """What a filter publishes at the prediction epochs of a gap."""

    NONE = "none"
    """The EKF's predictions (it coasts)."""
    RESIDUAL = "residual"
    """The motion model plus its residual learned from past pass ends (`GapForecaster`)."""
    BATCH_FIT = "batch_fit"
    """A batch least-squares fit of the last passes (`batch_gap.BatchGapForecaster`)."""
    BATCH_INIT = "batch_init"
    """`BATCH_FIT`, and the EKF starts each pass from the fit: at a pass's first real
    measurement its state and covariance are the fit's prediction there
    (`batch_gap.BatchGapForecaster.prior`, `tracker.Tracker.restart_from`), not its own
    coasted ones; the sequential update inside the pass goes on from them."""
    FIT_RESIDUAL = "fit_residual"
    """`BATCH_INIT` with the fit's predictions corrected by the residual surrogate learnt
    against the fit: the fits' states at the pass ends of the last 2 days, against the newest
    fit's trajectory (`fit_residual.FitResidualForecaster`); the fit's own until the
    surrogate can fit."""


_FITTED: dict[GapFill, type[BatchGapForecaster]] = {
    GapFill.BATCH_FIT: BatchGapForecaster, GapFill.BATCH_INIT: BatchGapForecaster,
    GapFill.FIT_RESIDUAL: FitResidualForecaster}
"""The gap fills that fit the last passes, and their forecaster."""
_RESTARTED = (GapFill.BATCH_INIT, GapFill.FIT_RESIDUAL)
"""The gap fills whose forecast is the EKF's prior of each pass."""


class GapForecast(Protocol):
    """A forecaster of a filter's gaps (`gap_forecaster.GapForecaster` is one)."""

    period_s: float
    fitted_t: float

    def on_estimate(self, t: float, x: ArrayLike, P: ArrayLike) -> None:
        """Take the filter's estimate at epoch t (s) after it fused a real measurement."""

    def forecast(self, t: float) -> tuple[Array, Array] | None:
        """Return the state and covariance at gap epoch t (s), or None where it has none."""

    def on_measurement(self, m: Measurement) -> None:
        """Take a real measurement the filter fused (epoch order)."""


@dataclass
class Published:
    """What the filter publishes after one input or one clock advance.

    Attributes
    ----------
    estimates : list of StateEstimate
        To publish, in this order.
    outcome : Outcome or None
        What the tracker did with the measurement (`GapPublisher.measurement` only).
    skipped : int
        Prediction epochs skipped: more were due at once than a call publishes.
    ran_ahead_s : float
        When some were skipped: how far (s) the clock was past the last prediction.
    """

    estimates: list[StateEstimate] = field(default_factory=list)
    outcome: Outcome | None = None
    skipped: int = 0
    ran_ahead_s: float = 0.0


class GapPublisher:
    """The estimates a single-object filter publishes (see the module docstring).

    Parameters
    ----------
    tracker : Tracker
        The filter (its state is never changed by a prediction).
    period_s : float
        Sim s between predictions in a gap; 0: no predictions.
    forecaster : callable, optional
        ``forecaster(period_s)`` makes the gap forecaster (a new one after `reset`); None:
        the predictions are the EKF coasting.
    restart : bool
        The EKF starts each pass from the forecaster's prior (a `BatchGapForecaster`'s
        ``prior``; `GapFill.BATCH_INIT`).
    """

    def __init__(self, tracker: Tracker, period_s: float,
                 forecaster: Callable[[float], GapForecast] | None = None,
                 restart: bool = False) -> None:
        self.tracker = tracker
        self.period_s = float(period_s)
        self._make_forecaster = forecaster
        self.restart = restart
        self._restarted_from = -math.inf  # epoch of the fit the EKF last restarted from
        self.forecaster = self._new_forecaster()
        self.last_object = ""  # object id of the last measurement fused
        self._predicted_at = -math.inf  # epoch of the last prediction published
        self._prediction: StateEstimate | None = None  # and the EKF's prediction there

    @classmethod
    def of(cls, tracker: Tracker, period_s: float, fill: GapFill,
           c: EstimatorConfig, options: BatchOptions | None = None) -> GapPublisher:
        """Return the publisher of the filter of `c` that fills its gaps with `fill`.

        With `GapFill.RESIDUAL`, the residual of the filter's motion model
        (`GapForecaster.for_model`); with `GapFill.BATCH_FIT` and `GapFill.BATCH_INIT`,
        the batch fit of its last passes with its measurement model
        (`batch_gap.BatchGapForecaster`), with `BATCH_INIT` the EKF's prior of each pass;
        with `GapFill.FIT_RESIDUAL` that fit corrected by the residual surrogate
        (`fit_residual.FitResidualForecaster`), also the EKF's prior of each pass.
        ``options``: the fit's own (`batch_ls.BatchOptions`, e.g. the high-fidelity force
        model) instead of `batch_gap.gap_fit_options` of each window.
        """
        fill = GapFill(fill)
        if fill == GapFill.NONE:
            return cls(tracker, period_s)
        fitted = _FITTED.get(fill)
        if fitted is not None:
            model, clock = measurement_model(c), (c.jd0 - UNIX_EPOCH_JD) * DAY_S
            return cls(tracker, period_s,
                       lambda period: fitted(model, period, clock_unix0=clock,
                                             options=options),
                       restart=fill in _RESTARTED)
        motion = c.filter.motion.motion_model
        return cls(tracker, period_s,
                   lambda period: GapForecaster.for_model(str(motion), period))

    def _new_forecaster(self) -> GapForecast | None:
        if self._make_forecaster is None or self.period_s <= 0:
            return None
        return self._make_forecaster(self.period_s)

    def set_period(self, period_s: float) -> None:
        """Predict every `period_s` sim s from now on (0: never).

        A gap forecaster keeps what it learnt (its anchors) and tabulates anew.
        """
        self.period_s = float(period_s)
        if self.forecaster is not None and self.period_s > 0:
            self.forecaster.period_s = self.period_s
            self.forecaster.fitted_t = -math.inf
        else:
            self.forecaster = self._new_forecaster()

    def reset(self) -> None:
        """Forget everything (a backwards jump of sim time): the tracker and the forecaster."""
        self.tracker.reset()
        self.forecaster = self._new_forecaster()
        self._predicted_at = -math.inf
        self._prediction = None
        self._restarted_from = -math.inf

    def measurement(self, m: Measurement) -> Published:
        """Fuse `m`; return the estimates to publish: the predictions due before it, then its.

        Only a real measurement ends a gap: before it, every prediction due before its epoch
        (up to `PREDICTIONS_BEFORE_MEASUREMENT`).
        """
        out = Published()
        if m.source == Source.SENSOR:
            self._predict(math.nextafter(m.t, -math.inf), PREDICTIONS_BEFORE_MEASUREMENT, out)
            if self.restart:
                self._start_pass(m.t)
        outcome = self.tracker.process(m)
        out.outcome = outcome
        if not outcome.rejected:
            self.last_object = m.object_id
            if m.source == Source.SENSOR and self.forecaster is not None:
                self.forecaster.on_measurement(m)
        for e in (outcome.estimate, *outcome.fused_again):  # fused again even if m was not
            if e is not None:
                out.estimates.append(self._published(e))
        return out

    def _start_pass(self, t: float) -> None:
        """At the first real measurement of a pass (epoch t), restart the EKF from the fit.

        Once per fit (a pass whose first measurements the gate refuses goes on from the
        restarted state, and the filter can still lose its object and initialise again),
        and only from a fit of a full window (the forecaster's ``passes`` passes): right
        after the initial orbit determination a window of one pass of a few angles can fit
        an orbit thousands of km off that the filter, restarted from it, would follow.
        """
        f, tracker = self.forecaster, self.tracker
        if (not isinstance(f, BatchGapForecaster) or not tracker.initialised
                or t - tracker.t_real <= f.pass_break_s or len(f.starts) < f.passes):
            return
        prior = f.prior(t)
        if prior is None or f.fitted_t == self._restarted_from:
            return
        self._restarted_from = f.fitted_t
        tracker.restart_from(StateEstimate(t=t, x=prior[0], P=prior[1],
                                           object_id=self.last_object))

    def advance(self, now: float, limit: int = PREDICTIONS_PER_CALL) -> Published:
        """Return the predictions due on the grid up to sim time `now` (s), at most `limit`.

        The epoch `now` itself included: a measurement stamped `now` that is still on its
        way comes after its prediction (the clock of an epoch may reach a node before what
        was measured at it, on another topic).
        """
        out = Published()
        self._predict(now, limit, out)
        return out

    def next_decision(self) -> float:
        """Return the earliest sim time (s) at which `advance` would publish (inf: none).

        The first prediction epoch due, once nothing was fused for `period_s` (none before
        the filter starts, or without predictions).
        """
        tracker = self.tracker
        if self.period_s <= 0 or not tracker.initialised:
            return math.inf
        after = max(tracker.t, self._predicted_at)
        first = (math.floor(after / self.period_s) + 1) * self.period_s
        return max(first, math.nextafter(tracker.t + self.period_s, math.inf))

    def _published(self, e: StateEstimate) -> StateEstimate:
        """Tag `e` with its object; an update's estimate goes to the forecaster too."""
        e.object_id = e.object_id or self.last_object
        if self.forecaster is not None and e.update_source == UpdateSource.SENSOR:
            self.forecaster.on_estimate(e.t, e.x, e.P)
        return e

    def _predict(self, now: float, limit: int, out: Published) -> None:
        """Add to `out` the predictions due up to `now` (at most `limit`)."""
        if self.period_s <= 0:
            return
        tracker = self.tracker
        if not tracker.initialised or tracker.t >= now - self.period_s:
            return  # nothing to predict from, or recently updated
        epochs, skipped = prediction_epochs(max(tracker.t, self._predicted_at), now,
                                            self.period_s, limit)
        if skipped:
            out.skipped += skipped
            out.ran_ahead_s = now - self._predicted_at
        for t in epochs:  # on the grid of multiples of period_s, chained
            last = self._prediction
            if last is not None and last.t >= tracker.t:
                e: StateEstimate | None = tracker.predict_from(last, t)
            else:
                e = tracker.predicted(t)
            if e is None:
                return
            f = self.forecaster.forecast(t) if self.forecaster is not None else None
            shown = e if f is None else StateEstimate(t=t, x=f[0], P=f[1], object_id=e.object_id,
                                                      update_source=UpdateSource.FORECAST)
            out.estimates.append(self._published(shown))
            self._predicted_at = t
            self._prediction = e  # the EKF's own prediction chain goes on
