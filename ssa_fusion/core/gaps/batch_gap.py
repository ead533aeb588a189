"""A batch fit over the last passes, as a filter's gap forecaster.

What a flight-dynamics engineer does between passes, on the filter's live stream: once the
filter has fused nothing for `pass_break_s`, the real measurements it fused in its last
passes (`GapWindow`, `pass_windows.fit_window`: those that start within `GAP_FIT_SPAN_H` of
the last measurement, `GAP_FIT_SPAN_H_ANGLES` for angles only, at least `GAP_FIT_PASSES`, at
most `GAP_FIT_MAX_MEASUREMENTS` measurements) are fitted by batch least squares
(`batch_ls.fit`, from the filter's estimate at the last of them, with `gap_fit_options`:
two-body + J2-J4 + drag, the state and drag factor, a realistic covariance with considered
accelerations and state-noise compensation), and the fit's prediction is tabulated
once on the grid of multiples of ``period_s`` up to ``max_horizon_s`` after the pass. It is
a `gap_publisher.GapForecast`: the filter publishes it at the gap's prediction epochs
(update source FORECAST); the EKF itself coasts on, and the next real measurement updates
the EKF's own prediction.

The same fit is the ``batch_fit`` arm of the evaluation (`evaluation.arms.batch_fit`).
Units: km, km/s, s; states GCRF.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.types import Kind, Measurement
from ssa_fusion.core.earth.timescales import DAY_S
from ssa_fusion.core.gaps.calibration import SCALE_PASSES, CovarianceScale
from ssa_fusion.core.measure.measurement import MeasurementModel
from ssa_fusion.core.measure.pass_windows import PASS_BREAK_S, passes, window_start
from ssa_fusion.core.motion.force_model import ForceModel
from ssa_fusion.core.od import batch_ls
from ssa_fusion.core.od.batch_ls import BatchFit, BatchOptions, FitStatus

__all__ = ["GAP_FIT", "GAP_FIT_ACCEL_SIGMA", "GAP_FIT_ANGLES", "GAP_FIT_MAX_MEASUREMENTS",
           "GAP_FIT_PASSES", "GAP_FIT_SNC", "GAP_FIT_SNC_ANGLES", "GAP_FIT_SOLVE_T_SPAN_H",
           "GAP_FIT_SPAN_H", "GAP_FIT_SPAN_H_ANGLES", "BatchGapForecaster", "GapWindow",
           "fit_passes", "gap_fit_options", "gap_window", "has_ranges", "solving_accel_t",
           "with_accel_sigma"]

Array = NDArray[np.float64]

GAP_FIT_PASSES = 3
"""The fewest passes of real measurements a gap's batch fit spans (all of them when fewer
exist): its last passes, whatever `GAP_FIT_SPAN_H`."""

GAP_FIT_SPAN_H = 24.0
"""Hours before its last measurement within which a pass must start to join the window of a
gap fit with ranges beyond its last `GAP_FIT_PASSES` (0: exactly those). Three passes of one
radar often fall on consecutive orbits within 3 h: the drag factor and the along-track
motion are then barely observed, and the fit errs by hundreds of metres a day later. A day
of passes observes them. Chosen of {0, 12, 24, 48} h on the tuning runs
(`bench/bench_sky.py --tuning --gap-fit-span-h H`, seeds 1-3 x start 0/8/16 h, with the
accelerations considered at 1.5e-8 km/s^2; medians over runs of the published `batch_init`
error at all gap epochs / over gaps > 12 h): iss_radar_columbus 0.266 / 0.388 km (0 h),
0.082 / 0.107 (12 h), 0.062 / 0.063 (24 h), 0.052 / 0.079 (48 h); with 24 h iss_network
0.029 / 0.014 km (0 h: 0.100 / 3.39) and iss_network_april 0.030 / 0.010 km (0 h: 0.067 /
1.96). 24 h: the smallest error over the long gaps. Solving for the along-track acceleration
as well gained nothing there (`GAP_FIT_SOLVE_T_SPAN_H`). Its cost (`bench/bench_batch_ls.py
--drag-sigma 10 --snc 1e-14 --span-h 24`, seed 1, J2-J4 + drag): a re-fit of a day of one
radar (161 measurements median, 200 at most) 28 ms median, 43 ms at most, against 12.7 /
33 ms for three passes (89 / 114 measurements); `GAP_FIT_MAX_MEASUREMENTS` bounds a
network's."""

GAP_FIT_SPAN_H_ANGLES = 0.0
"""The same for a window of angles only (optical sites): its last `GAP_FIT_PASSES` passes.
On leo_optical's tuning runs a 24 h window (with `GAP_FIT_SNC_ANGLES`) erred by 0.038 /
0.055 km and covered 88.6 % of the gap epochs' NEES (below the 90 % of the target); with
three passes the evaluation runs meet every target (docs/RESULTS.md)."""

GAP_FIT_MAX_MEASUREMENTS = 600
"""The most measurements a gap fit's window holds: beyond it its oldest passes go (never one
of its last `GAP_FIT_PASSES`); it bounds a re-fit's time where a network sees many passes.
A bound of the cost, not chosen on the data (three passes of a network hold up to 260)."""


def has_ranges(window: list[Measurement]) -> bool:
    """Whether a measurement of `window` has a range (its fit is `GAP_FIT`'s, not angles')."""
    return any(m.kind in (Kind.RANGE_AZ_EL, Kind.POSITION) for m in window)


@dataclass(frozen=True)
class GapWindow:
    """Which passes a gap fit spans (`pass_windows.fit_window`).

    ``passes``: the fewest (the last ones); ``span_h``: h before the window's last measurement
    within which an earlier pass must start to join, for a window with ranges
    (``span_h_angles`` for one of angles only: whether the passes the wider of the two spans
    would hold have a range decides); ``max_measurements``: the cap.
    """

    passes: int = GAP_FIT_PASSES
    span_h: float = GAP_FIT_SPAN_H
    max_measurements: int | None = GAP_FIT_MAX_MEASUREMENTS
    span_h_angles: float = GAP_FIT_SPAN_H_ANGLES

    def select(self, measurements: list[Measurement], before: float = math.inf,
               gap_s: float = PASS_BREAK_S) -> list[Measurement]:
        """Return the window of `measurements` (epoch order) before epoch `before` (s).

        `gap_s`: the break (s) between passes.
        """
        earlier = [m for m in measurements if m.t < before]
        return earlier[self.start(earlier, gap_s):]

    def start(self, measurements: list[Measurement], gap_s: float = PASS_BREAK_S) -> int:
        """Return the index of the window's first measurement in `measurements`.

        All of `measurements` before the window's end; `gap_s` as `select`.
        """
        wide = self.keep(measurements, gap_s)
        span = self.span_h if has_ranges(measurements[wide:]) else self.span_h_angles
        return window_start(measurements, self.passes, 3600.0 * span, self.max_measurements,
                            gap_s)

    def keep(self, measurements: list[Measurement], gap_s: float = PASS_BREAK_S) -> int:
        """Return the index of the first measurement a later window could still span.

        The window of the wider span: a window only moves forward (its last measurement and
        its passes only grow), so what is before it no later window of either span holds.
        """
        return window_start(measurements, self.passes,
                            3600.0 * max(self.span_h, self.span_h_angles),
                            self.max_measurements, gap_s)


def gap_window() -> GapWindow:
    """Return the window of the module's settings (read at the call)."""
    return GapWindow(GAP_FIT_PASSES, GAP_FIT_SPAN_H, GAP_FIT_MAX_MEASUREMENTS,
                     GAP_FIT_SPAN_H_ANGLES)

GAP_FIT_SNC = 1e-15
"""Power spectral density of the gap fit's state-noise compensation, km^2/s^3 in R, T and N
alike, for a window with ranges (radar): white accelerations between the measurements and
through the gap, beside the considered constant ones (`GAP_FIT_ACCEL_SIGMA`), which carry
the level. White noise grows the position variance through a gap as q t^3 / 3 (1e-14: 0.5
km of sigma after 12 h) while the error of a fit of a day of passes stays near 0.07 km: at
1e-14 the covariance was cautious on the evaluation runs (median NEES 0.41 with one radar,
0.31 / 0.36 with the networks). The smallest of {1e-15, 3e-15, 1e-14} whose position NEES
over the gap epochs lies inside chi2(3)'s 95 % bound at >= 90 % of them (median over runs of
the published `batch_init`) on every ranged scenario's tuning runs, the first ten tuning
seeds this time (`bench/bench_sky.py --tuning --tuning-seeds 10 --gap-fit-snc Q`: seeds
1-10 x start 0/8/16 h; three seeds are three geometries, too few: on seeds 1-3 1e-14 gave
one radar a median NEES of 1.48, on seeds 1-10 0.32). 1e-15: iss_radar_columbus 96.4 %,
median NEES 1.26; iss_network 96.6 %, 1.54; iss_network_april 92.5 %, 1.48 (3e-15, one
radar: 98.9 %, 0.74). On seeds 1-10, with 1e-14, the considered accelerations hardly mattered
(one radar's median NEES 0.36 / 0.34 / 0.32 at 2.5e-9 / 3.5e-9 / 5e-9 km/s^2): the white
noise was the covariance. Before, with three-pass windows, 1e-13 and then 1e-14 had been
chosen for coverage. The fit's state does not depend on it."""

GAP_FIT_SNC_ANGLES = 3e-15
"""The same for a window of angles only (optical sites), white noise alone: the smallest of
{1e-15, 3e-15, 1e-14, 3e-14, 1e-13, 3e-13} whose coverage is >= 90 % on leo_optical's tuning
runs (91.9 %; 1e-15: 77.8 %, 1e-14: 96.8 %).
Its windows span more time than a radar network's three passes, and its gap error is
smaller: the same unmodelled acceleration shows less."""

GAP_FIT_DRAG_SIGMA = 10.0
"""A priori standard deviation of the gap fit's drag factor (nominal 1): the data, not the
prior, set it. With 1 a drag-free LEO orbit was fitted with drag pulled toward the nominal
(0.33 km off an hour later, `test_arms`); on the tuning seeds 1-3 of iss_radar_columbus the
gap error is 0.209 / 0.161 / 0.189 km with 10, 0.125 / 0.18 / 0.217 km with 1."""

GAP_FIT_ACCEL_SIGMA = 3e-7
"""Standard deviation (km/s^2) of the constant accelerations in R, T and N alike that the
gap fit of a window with ranges considers (`batch_ls` consider parameters ``accel_r``,
``accel_t``, ``accel_n``): what its model (J2-J4 + drag) leaves out of the world (the
high-fidelity truth's 20 x 20 geopotential, Sun, Moon, SRP, NRLMSISE-00 drag), mapped into
the fit's state through the window -- a floor that more measurements do not lower -- and
grown through the gap (as t^2). Not a force of nature: the size of the model error,
3e-4 m/s^2. The smallest of {5e-9, 3e-8, 5e-8, 1e-7, 1.5e-7, 2e-7, 3e-7} whose median
position NEES at the gap epochs (of what the filter publishes, `batch_init`, median over
runs) is at most 3.7 (chi2(3)'s median 2.37 with sigma within +20 %) on both ranged ISS
scenarios' tuning runs with the high-fidelity truth (`bench/bench_sky.py --gaps-only
--tuning --gap-fit-accel A`, seeds 1-3 x start 0/8/16 h): iss_radar_columbus 3.19 / 2.81 /
2.83 and iss_network 4.45 / 4.00 / 3.52 at 1.5e-7 / 2e-7 / 3e-7 (start 0 h alone: one radar
5.78 / 3.59 / 2.90 / 2.52 at 5e-9 / 3e-8 / 5e-8 / 1e-7, the network 5.67 / 5.22 / 5.65 /
4.81). The along-track one alone at 3e-7 (R and N at 5e-9) gave 11.4 / 13.7: the world's
radial and cross-track errors count too. The price: the covariance of the fit becomes the
EKF's prior at the next pass (`GapFill.BATCH_INIT`), and the estimate right after a pass
erred by 0.121 / 0.134 km (one radar / network, medians over the tuning runs) against
0.090 / 0.069 km at 5e-9, whose covariance was 2.4x too small (median NEES 5.78 / 5.67
before the calibration, `calibration`, widened it; 440 without). With the SGP4 truth, whose
model error is far smaller, 5e-9 was right (median NEES 1.48 / 2.18): the setting is that
of the world the filter runs in. The fit's state does not depend on it."""

GAP_FIT_SCORED_FITS = 3
"""How many of the last fits the calibration scores on each pass (`BatchGapForecaster`):
the last one at one gap's horizon, the ones before at two and three. One radar's first
passes, an orbit apart, then score horizons of several hours before its first long gap,
and beyond them the excess grows less far (`calibration.EXCESS_POWER`). On the tuning runs
with the high-fidelity truth (`bench/bench_sky.py --gaps-only --tuning`, seeds 1-3 x start
0/8/16 h; median over runs of `batch_init`'s median position NEES at gap epochs / its
coverage of chi2(3)'s 95 % bound): one radar 2.83 / 65.6 % with 1, 2.33 / 68.2 % with 3;
the network 1.97 / 66.9 % and 2.33 / 69.8 %."""

GAP_FIT_SOLVE_T_SPAN_H = math.inf
"""Hours a ranged window must span (first to last measurement) for its fit to solve for the
constant along-track acceleration ``accel_t`` (a priori `GAP_FIT_ACCEL_SIGMA`) beside the
drag factor, instead of considering it (inf: never). Never: on iss_radar_columbus's tuning
runs with 24 h windows (`--gap-fit-solve-t-span-h 12`, accelerations 1.5e-8 km/s^2) the
error at all gap epochs / over gaps > 12 h was 0.066 / 0.072 km against 0.062 / 0.063 km
considering it: over a day the drag factor already takes what a constant along-track
acceleration would."""

_ACCELS = ("accel_r", "accel_t", "accel_n")


def with_accel_sigma(options: BatchOptions, sigma: float) -> BatchOptions:
    """Return `options` considering constant R, T, N accelerations of `sigma` km/s^2.

    Their standard deviation, in each axis; none for 0 (the options' own stay).
    """
    if sigma <= 0.0:
        return replace(options, consider=())
    return replace(options, consider=_ACCELS,
                   param_sigma=(options.param_sigma[0], float(sigma), float(sigma), float(sigma)))


GAP_FIT = with_accel_sigma(
    BatchOptions(force=ForceModel(drag=True), solve_for=("drag_scale",),
                 snc_psd=(GAP_FIT_SNC,) * 3, param_sigma=(GAP_FIT_DRAG_SIGMA, 1e-8, 1e-8, 1e-8)),
    GAP_FIT_ACCEL_SIGMA)
"""The gap fit of a window with ranges: two-body + J2-J4 + drag, the state and the drag
factor solved for, constant R, T, N accelerations considered (`GAP_FIT_ACCEL_SIGMA`),
state-noise compensation `GAP_FIT_SNC`. On the tuning seeds 1-3 of iss_radar_columbus
(`bench/bench_batch_ls.py` ``--drag-sigma 10``) its gap error was 0.209 / 0.161 / 0.189 km
(medians); with the state alone (J2-J4) 0.314 / 0.261 / 0.218 km, with J2 + drag (J3, J4
left out) 0.224 / 0.201 / 0.271 km (the noise and the considered accelerations do not change
the fit's state). Where there is no air the drag factor is unobserved and stays at its prior
(no effect)."""

GAP_FIT_ANGLES = BatchOptions(snc_psd=(GAP_FIT_SNC_ANGLES,) * 3)
"""The gap fit of a window of angles only: two-body + J2-J4, the state only (a drag factor
is too weakly observed by angles over three passes), `GAP_FIT_SNC_ANGLES`."""


def gap_fit_options(window: list[Measurement]) -> BatchOptions:
    """Return the options of the gap fit of `window` (epoch order).

    `GAP_FIT_ANGLES` when no measurement of `window` has a range; else `GAP_FIT`, solving for
    the along-track acceleration too (`solving_accel_t`) when the window spans at least
    `GAP_FIT_SOLVE_T_SPAN_H`.
    """
    if not has_ranges(window):
        return GAP_FIT_ANGLES
    if window[-1].t - window[0].t >= 3600.0 * GAP_FIT_SOLVE_T_SPAN_H:
        return solving_accel_t(GAP_FIT)
    return GAP_FIT


def solving_accel_t(options: BatchOptions) -> BatchOptions:
    """Return `options` solving for ``accel_t`` (a priori its considered sigma) too."""
    return replace(options, solve_for=(*options.solve_for, "accel_t"),
                   consider=tuple(p for p in options.consider if p != "accel_t"))

_FAILED = (FitStatus.DIVERGED, FitStatus.UNDERDETERMINED)


def fit_passes(window: list[Measurement], model: MeasurementModel, x_guess: ArrayLike,
               t_guess: float, clock_unix0: float = 0.0,
               options: BatchOptions | None = None) -> BatchFit | None:
    """Fit `gap_fit_options(window)` (or ``options``) to `window`; None if it fails.

    It fails when it diverges, is underdetermined or has no model for a measurement.
    `clock_unix0`: Unix time (s) of t = 0 of the measurements' clock.
    """
    if not window:
        return None
    opts = replace(gap_fit_options(window) if options is None else options,
                   clock_unix0=float(clock_unix0))
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
    last estimate, beyond ``max_horizon_s``, or no fit (it failed); `prior(t)` the same at
    any epoch t, the first measurement of the next pass. ``options``: the fit's (None:
    `gap_fit_options` of each window); ``cpu_s``: the process CPU time its fits and their
    tabulations took, s. With ``calibrate`` the covariances published are the fit's times
    ``scale``'s factor, measured on the object's own last passes (`calibration`): each pass
    scores the last ``scored_fits`` fits (``older``: the ones before the last, with the
    epochs of their passes' ends), and ``scale`` keeps the estimates of `SCALE_PASSES`
    passes.
    """

    model: MeasurementModel
    period_s: float
    clock_unix0: float = 0.0
    passes: int = field(default_factory=lambda: GAP_FIT_PASSES)
    span_h: float = field(default_factory=lambda: GAP_FIT_SPAN_H)
    max_measurements: int | None = field(default_factory=lambda: GAP_FIT_MAX_MEASUREMENTS)
    span_h_angles: float = field(default_factory=lambda: GAP_FIT_SPAN_H_ANGLES)
    pass_break_s: float = PASS_BREAK_S
    max_horizon_s: float = DAY_S
    window: list[Measurement] = field(default_factory=list)
    starts: list[int] = field(default_factory=list)
    last: tuple[float, Array] | None = None
    fitted_t: float = -math.inf
    fit: BatchFit | None = None
    table: dict[float, tuple[Array, Array]] = field(default_factory=dict)
    options: BatchOptions | None = None
    cpu_s: float = 0.0
    calibrate: bool = True
    scored_fits: int = field(default_factory=lambda: GAP_FIT_SCORED_FITS)
    older: list[tuple[float, BatchFit]] = field(default_factory=list)
    scale: CovarianceScale = field(default_factory=lambda: CovarianceScale(
        passes=SCALE_PASSES * GAP_FIT_SCORED_FITS))

    @property
    def rule(self) -> GapWindow:
        """The window's rule: ``passes``, ``span_h``, ``max_measurements``, ``span_h_angles``."""
        return GapWindow(self.passes, self.span_h, self.max_measurements, self.span_h_angles)

    def on_measurement(self, m: Measurement) -> None:
        """Take a real measurement the filter fused; keep those a window can still span.

        At the first measurement of a pass the passes no later window can hold are forgotten
        (a window only moves forward: its last measurement and passes only grow).
        """
        if self.window and m.t <= self.window[-1].t:
            return
        self.window.append(m)
        if len(self.window) == 1 or m.t - self.window[-2].t > self.pass_break_s:
            del self.window[:self.rule.keep(self.window, self.pass_break_s)]
            self.starts = [a for a, _ in passes(self.window, self.pass_break_s)]

    def on_estimate(self, t: float, x: ArrayLike, P: ArrayLike) -> None:
        """Take the filter's estimate (epoch t s) after it fused a real measurement."""
        if self.last is None or t > self.last[0]:
            self.last = (float(t), np.asarray(x, float).copy())

    def forecast(self, t: float) -> tuple[Array, Array] | None:
        """Return the fit's state and covariance at gap epoch t (s), or None."""
        if self.last is None or t - self.last[0] < self.pass_break_s:
            return None
        self._refit()
        return self.table.get(float(t))

    def prior(self, t: float) -> tuple[Array, Array] | None:
        """Return the fit's prediction to epoch t (s): state and realistic covariance.

        The prior of the pass that starts at t (`gap_publisher.GapFill.BATCH_INIT`): None
        when t is less than `pass_break_s` or more than ``max_horizon_s`` after the last
        estimate, or when there is no fit (it failed) or its prediction failed.
        """
        if self.last is None or not (self.pass_break_s <= t - self.last[0]
                                     <= self.max_horizon_s):
            return None
        self._refit()
        if self.fit is None:
            return None
        try:
            xs, Ps = self.fit.predict(np.array([float(t)]))
        except (ValueError, ArithmeticError, np.linalg.LinAlgError):
            return None
        if not (np.isfinite(xs).all() and np.isfinite(Ps).all()):
            return None
        return xs[0], Ps[0] * float(self.scale.factor(float(t) - self.last[0])[0])

    def _refit(self) -> None:
        """Fit the window once after each pass (at its last estimate) and tabulate the gap.

        Before, the forecast published for the pass just ended is scored on its
        measurements (`calibration.CovarianceScale`); the table's covariances are scaled
        by the factor.
        """
        assert self.last is not None
        t_end, x_end = self.last
        if self.fitted_t != t_end:  # a pass ended: fit once, tabulate the prediction
            cpu = time.process_time()
            self._calibrate(self.fitted_t, t_end)
            self.fitted_t = t_end
            self.table = {}
            window = self.window[self.rule.start(self.window, self.pass_break_s):]
            self.fit = fit_passes(window, self.model, x_end, t_end, self.clock_unix0,
                                  self.options)
            k0 = math.floor(t_end / self.period_s) + 1
            k1 = math.floor((t_end + self.max_horizon_s) / self.period_s)
            grid = self.period_s * np.arange(k0, k1 + 1, dtype=float)
            if self.fit is not None and grid.size:
                try:  # a propagation that fails leaves the gap to the EKF's coasting
                    xs, Ps = self.fit.predict(grid)
                except (ValueError, ArithmeticError, np.linalg.LinAlgError):
                    xs, Ps = np.full((grid.size, 6), np.nan), np.full((grid.size, 6, 6), np.nan)
                Ps = Ps * self.scale.factor(grid - t_end)[:, None, None]
                self.table = {float(g): (xs[i], Ps[i]) for i, g in enumerate(grid)
                              if np.isfinite(xs[i]).all() and np.isfinite(Ps[i]).all()}
            self.cpu_s += time.process_time() - cpu

    def _calibrate(self, before: float, t_end: float) -> None:
        """Score the last ``scored_fits`` fits on the pass that ended at ``t_end``.

        The last fit was published at ``before``, the ones before it (``older``) at their
        own passes' ends: each is scored at its horizon, from there to the pass's mean epoch.
        """
        if not self.calibrate:
            return
        ms = [m for m in self.window if before < m.t <= t_end]
        t = np.array([m.t for m in ms])
        scored = [*self.older, (before, self.fit)] if ms else []
        for t_fit, fit in [(a, f) for a, f in scored if f is not None]:
            try:
                x, P = fit.predict(t)
            except (ValueError, RuntimeError, ArithmeticError, np.linalg.LinAlgError):
                continue
            self.scale.update(ms, self.model, x, P, horizon_s=float(t.mean()) - t_fit)
        if self.fit is not None:
            self.older.append((before, self.fit))
            del self.older[:max(len(self.older) - (self.scored_fits - 1), 0)]
