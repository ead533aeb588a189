"""A batch fit over the last passes, as a filter's gap forecaster.

What a flight-dynamics engineer does between passes, on the filter's live stream: once the
filter has fused nothing for `pass_break_s`, the real measurements it fused in its last
`GAP_FIT_PASSES` passes are fitted by batch least squares (`batch_ls.fit`, from the
filter's estimate at the last of them, with `GAP_FIT`'s options: two-body + J2, the state,
a realistic covariance with state-noise compensation), and the fit's prediction is tabulated
once on the grid of multiples of ``period_s`` up to ``max_horizon_s`` after the pass. It is
a `gap_publisher.GapForecast`: the filter publishes it at the gap's prediction epochs
(update source FORECAST); the EKF itself coasts on, and the next real measurement updates
the EKF's own prediction.

The same fit is the ``batch_fit`` arm of the evaluation (`evaluation.arms.batch_fit`).
Units: km, km/s, s; states GCRF.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import batch_ls
from .batch_ls import BatchFit, BatchOptions, FitStatus
from .force_model import ForceModel
from .measurement import MeasurementModel
from .pass_windows import PASS_BREAK_S
from .timescales import DAY_S
from .types import Kind, Measurement

__all__ = ["GAP_FIT", "GAP_FIT_ANGLES", "GAP_FIT_PASSES", "GAP_FIT_SNC", "GAP_FIT_SNC_ANGLES",
           "BatchGapForecaster", "fit_passes", "gap_fit_options"]

Array = NDArray[np.float64]

GAP_FIT_PASSES = 3
"""Passes of real measurements a gap's batch fit spans."""

GAP_FIT_SNC = 1e-13
"""Power spectral density of the gap fit's state-noise compensation, km^2/s^3 in R, T and N
alike, for a window with ranges (radar): ~ 6e-9 km/s^2 of unmodelled acceleration
correlated over ~ 3e3 s (a^2 tau). The smallest of {1e-15, 3e-15, 1e-14, 3e-14, 1e-13,
3e-13} whose position NEES over the gap epochs lies inside chi2(3)'s 95 % bound at >= 90 %
of them (median over runs) on each ranged scenario's tuning runs (`bench/bench_sky.py
--tuning`: seeds 1-3 x start 0/8/16 h of iss_radar_columbus, iss_network,
iss_network_april: 99.4 / 95.0 / 93.7 %; 3e-14: 98.5 / 87.6 / 80.3 %), never on an
evaluation seed. The fit's state does not depend on it."""

GAP_FIT_SNC_ANGLES = 3e-15
"""The same for a window of angles only (optical sites): the smallest of the same set whose
coverage is >= 90 % on leo_optical's tuning runs (91.9 %; 1e-15: 77.8 %, 1e-14: 96.8 %).
Its windows span more time than a radar network's three passes, and its gap error is
smaller: the same unmodelled acceleration shows less."""

GAP_FIT_DRAG_SIGMA = 10.0
"""A priori standard deviation of the gap fit's drag factor (nominal 1): the data, not the
prior, set it. With 1 a drag-free LEO orbit was fitted with drag pulled toward the nominal
(0.33 km off an hour later, `test_arms`); on the tuning seeds 1-3 of iss_radar_columbus the
gap error is 0.209 / 0.161 / 0.189 km with 10, 0.125 / 0.18 / 0.217 km with 1."""

GAP_FIT = BatchOptions(force=ForceModel(drag=True), solve_for=("drag_scale",),
                       snc_psd=(GAP_FIT_SNC,) * 3,
                       param_sigma=(GAP_FIT_DRAG_SIGMA, 1e-8, 1e-8, 1e-8))
"""The gap fit of a window with ranges: two-body + J2-J4 + drag, the state and the drag
factor. On the tuning seeds 1-3 of iss_radar_columbus (`bench/bench_batch_ls.py`
``--drag-sigma 10``) its gap error was 0.209 / 0.161 / 0.189 km (medians);
with the state alone (J2-J4) 0.314 / 0.261 / 0.218 km, with J2 + drag (J3, J4 left out)
0.224 / 0.201 / 0.271 km (at SNC 3e-14; the SNC does not change the fit's state). Where
there is no air the drag factor is unobserved and stays at its prior (no effect)."""

GAP_FIT_ANGLES = BatchOptions(snc_psd=(GAP_FIT_SNC_ANGLES,) * 3)
"""The gap fit of a window of angles only: two-body + J2-J4, the state only (a drag factor
is too weakly observed by angles over three passes), `GAP_FIT_SNC_ANGLES`."""


def gap_fit_options(window: list[Measurement]) -> BatchOptions:
    """Return `GAP_FIT`, or `GAP_FIT_ANGLES` when no measurement of `window` has a range."""
    ranged = any(m.kind in (Kind.RANGE_AZ_EL, Kind.POSITION) for m in window)
    return GAP_FIT if ranged else GAP_FIT_ANGLES

_FAILED = (FitStatus.DIVERGED, FitStatus.UNDERDETERMINED)


def fit_passes(window: list[Measurement], model: MeasurementModel, x_guess: ArrayLike,
               t_guess: float, clock_unix0: float = 0.0) -> BatchFit | None:
    """Fit `gap_fit_options(window)` to `window`; None if it fails.

    It fails when it diverges, is underdetermined or has no model for a measurement.
    `clock_unix0`: Unix time (s) of t = 0 of the measurements' clock.
    """
    if not window:
        return None
    opts = replace(gap_fit_options(window), clock_unix0=float(clock_unix0))
    try:
        fit = batch_ls.fit(window, model, np.asarray(x_guess, float)[:6], t_guess, opts)
    except ValueError:  # a measurement the fit has no model for
        return None
    return None if fit.status in _FAILED else fit


@dataclass
class BatchGapForecaster:
    """The batch fit of the last passes on a filter's live stream (module docstring).

    `on_measurement` takes every real measurement the filter fused (epoch order),
    `on_estimate` the filter's estimate after it. `forecast(t)` returns the fit's state and
    covariance at a grid epoch t of the gap, or None: t less than `pass_break_s` after the
    last estimate, beyond ``max_horizon_s``, or no fit (it failed).
    """

    model: MeasurementModel
    period_s: float
    clock_unix0: float = 0.0
    passes: int = GAP_FIT_PASSES
    pass_break_s: float = PASS_BREAK_S
    max_horizon_s: float = DAY_S
    window: list[Measurement] = field(default_factory=list)
    starts: list[int] = field(default_factory=list)
    last: tuple[float, Array] | None = None
    fitted_t: float = -math.inf
    fit: BatchFit | None = None
    table: dict[float, tuple[Array, Array]] = field(default_factory=dict)

    def on_measurement(self, m: Measurement) -> None:
        """Take a real measurement the filter fused; keep those of the last passes."""
        if self.window and m.t <= self.window[-1].t:
            return
        if not self.window or m.t - self.window[-1].t > self.pass_break_s:
            self.starts.append(len(self.window))
            if len(self.starts) > self.passes:  # forget the oldest pass
                k = self.starts[1]
                del self.window[:k]
                self.starts = [s - k for s in self.starts[1:]]
        self.window.append(m)

    def on_estimate(self, t: float, x: ArrayLike, P: ArrayLike) -> None:
        """Take the filter's estimate (epoch t s) after it fused a real measurement."""
        if self.last is None or t > self.last[0]:
            self.last = (float(t), np.asarray(x, float).copy())

    def forecast(self, t: float) -> tuple[Array, Array] | None:
        """Return the fit's state and covariance at gap epoch t (s), or None."""
        if self.last is None or t - self.last[0] < self.pass_break_s:
            return None
        t_end, x_end = self.last
        if self.fitted_t != t_end:  # a pass ended: fit once, tabulate the prediction
            self.fitted_t = t_end
            self.table = {}
            self.fit = fit_passes(self.window, self.model, x_end, t_end, self.clock_unix0)
            k0 = math.floor(t_end / self.period_s) + 1
            k1 = math.floor((t_end + self.max_horizon_s) / self.period_s)
            grid = self.period_s * np.arange(k0, k1 + 1, dtype=float)
            if self.fit is not None and grid.size:
                try:  # a propagation that fails leaves the gap to the EKF's coasting
                    xs, Ps = self.fit.predict(grid)
                except (ValueError, ArithmeticError, np.linalg.LinAlgError):
                    xs, Ps = np.full((grid.size, 6), np.nan), np.full((grid.size, 6, 6), np.nan)
                self.table = {float(g): (xs[i], Ps[i]) for i, g in enumerate(grid)
                              if np.isfinite(xs[i]).all() and np.isfinite(Ps[i]).all()}
        return self.table.get(float(t))
