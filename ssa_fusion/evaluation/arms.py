"""The evaluation arms over a gap: one definition and one scorer each.

Used by the offline study (`experiments`, which simulates) and by the evaluation of a
recorded bag (`ssa_fusion.apps.evaluate`), so a number in RESULTS.md and one in a live
report mean the same thing. Every arm is an `ArmTrajectory` (estimate and covariance at
each gap epoch), scored by `score` against the truth with the paper's normalised error ε,
the position error and the NEES.

* ``placeholder`` -- the filter's motion model alone: 200 particles drawn from the filter's
  estimate and covariance at the last real measurement before the gap (`start_estimate`),
  propagated by that model, never corrected; the ensemble mean and covariance (paper
  section 3, started where the gap starts rather than at the initial orbit determination);
* ``coast`` -- the same EKF predicting through the gap from the same estimate, with its
  process noise (x <- f(x), P <- F P F' + Q): what the graph does without a surrogate;
* ``j2_coast`` -- the physics-only filter an orbit-determination user would run: the same
  EKF settings and real measurements with a two-body + J2 motion model (and the process
  noise of what J2 leaves out, `J2_COAST_Q`), coasting through the gap (Earth orbits only);
* ``batch_fit`` -- the best physics-only estimate, what a flight-dynamics engineer would
  fit by hand: batch least squares over the real measurements of the last passes before
  the gap, two-body + J2, from the filter's estimate at the last of them, predicted through
  the gap with its realistic covariance (`core.gaps.batch_gap`: `gap_window`, `GAP_FIT`; the
  fit the filter publishes in gaps with ``gap_forecast: batch_fit``); Earth orbits only;
* ``dmd_ekf`` -- the filter's estimates at the gap epochs, fusing the surrogate's forecasts;
  at an epoch without one (no forecast, or one refused) its prediction from the last estimate
  before it, as the live filter would publish;
* ``hypothetical_ekf`` -- the same EKF given the gap's real measurements too (the sensor had
  not been out).

Units: the core's (km, km/s, rad, s).
"""

from __future__ import annotations

import bisect
import enum
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ssa_fusion.core.base.metrics import epsilon, nees
from ssa_fusion.core.base.types import (
    Measurement,
    MotionModel,
    Source,
    StateEstimate,
    UpdateSource,
    same_epoch,
)
from ssa_fusion.core.earth import frames
from ssa_fusion.core.earth.timescales import DAY_S, UNIX_EPOCH_JD
from ssa_fusion.core.gaps.batch_gap import fit_passes, gap_window
from ssa_fusion.core.gaps.estimator import (
    ORBIT_MODELS,
    EstimatorConfig,
    make_tracker,
    measurement_model,
)
from ssa_fusion.evaluation.montecarlo import N_PARTICLES, placeholder_ensemble

J2_COAST_Q = 1e-13
"""Process noise of the J2 filter, (km/s^2)^2 s, by the scenarios' rule q ~ a^2 tau (never
from the gap): a ~ 1e-8 km/s^2, what a J2 model leaves out in LEO (J3 and higher harmonics,
drag at 400 km), tau a quarter ISS period (1.4e3 s). The Keplerian filters' q (1e-7) is
sized for the J2 they leave out, ~1e3 times larger an acceleration."""


class ArmName(enum.StrEnum):
    """The arms, in the order tables list them."""

    PLACEHOLDER = "placeholder"
    COAST = "coast"
    J2_COAST = "j2_coast"
    BATCH_FIT = "batch_fit"
    DMD_EKF = "dmd_ekf"
    HYPOTHETICAL_EKF = "hypothetical_ekf"


@dataclass
class ArmTrajectory:
    """One arm's estimates at the gap epochs.

    t : (k,) epochs, s; x : (k, n) states; P : (k, n, n) covariances; source : (k,)
    `UpdateSource` of each estimate (NONE: a prediction).
    """

    t: np.ndarray
    x: np.ndarray
    P: np.ndarray
    source: np.ndarray


@dataclass
class ArmScore:
    """How close an arm stays to the truth over the gap.

    epsilon : the paper's normalised error (`metrics.epsilon`); pos_err_mean_km,
    pos_err_final_km : position error norm, mean over the gap and at its last epoch, km;
    nees : (k,) NEES per epoch (None if a covariance is not invertible); nees_mean its mean.
    """

    epsilon: float
    pos_err_mean_km: float
    pos_err_final_km: float
    nees: np.ndarray | None
    nees_mean: float | None


def _trajectory(estimates: list[StateEstimate]) -> ArmTrajectory:
    return ArmTrajectory(np.array([e.t for e in estimates]), np.array([e.x for e in estimates]),
                         np.array([e.P for e in estimates]),
                         np.array([e.update_source for e in estimates], dtype=int))


def score(arm: ArmTrajectory, x_true: np.ndarray) -> ArmScore:
    """Score `arm` against the true states (k, n) at its epochs.

    The first three state components are the position, km, for the position errors.
    """
    err = np.linalg.norm(arm.x[:, :3] - x_true[:, :3], axis=1)
    e: np.ndarray | None = None
    if np.all(np.isfinite(arm.P)):
        try:
            e = nees(arm.x - x_true, arm.P)
        except np.linalg.LinAlgError:
            e = None
    return ArmScore(epsilon(arm.x, x_true), float(np.mean(err)), float(err[-1]), e,
                    None if e is None else float(np.mean(e)))


def run_filter(c: EstimatorConfig, stream: Iterable[Measurement],
               object_id: str = "") -> dict[float, StateEstimate]:
    """Run the EKF of `c` over `stream` in epoch order; return the last estimate per epoch.

    A real measurement goes before a forecast of the same epoch.
    """
    tracker = make_tracker(c, object_id)
    out: dict[float, StateEstimate] = {}
    for m in sorted(stream, key=lambda m: (m.t, m.source)):
        o = tracker.process(m)
        for e in (o.estimate, *o.fused_again):
            if e is not None:
                out[e.t] = e
    return out


def start_estimate(estimates: Mapping[float, StateEstimate], t_gap0: float) -> StateEstimate:
    """Return the filter's estimate at its last real measurement before the gap.

    The gap starts at `t_gap0`; ValueError if the filter never updated on a real
    measurement before it.
    """
    before = [e for t, e in estimates.items()
              if t < t_gap0 and e.update_source == UpdateSource.SENSOR]
    if not before:
        raise ValueError("no estimate from a real measurement before the gap: the filter "
                         "never initialised")
    return max(before, key=lambda e: e.t)


def placeholder(c: EstimatorConfig, start: StateEstimate, t_gap: np.ndarray, seed: int,
                n_particles: int = N_PARTICLES) -> ArmTrajectory:
    """Return the motion model alone: Monte Carlo from `start` (see the module docstring)."""
    dt = np.concatenate([[0.0], t_gap - start.t])  # the ensemble starts at the estimate
    motion = c.filter.motion
    pole = (frames.pole_frame(start.t + (c.jd0 - UNIX_EPOCH_JD) * DAY_S)
            if motion.motion_model in ORBIT_MODELS else None)
    mean, cov = placeholder_ensemble(str(motion.motion_model), start.x, start.P, dt, seed,
                                     n_particles, pole, **motion.motion_params)
    return ArmTrajectory(np.asarray(t_gap, float), mean[1:], cov[1:],
                         np.full(len(t_gap), UpdateSource.NONE))


def coast(c: EstimatorConfig, start: StateEstimate, t_gap: np.ndarray) -> ArmTrajectory:
    """Return the EKF of `c` predicting from `start` epoch by epoch through the gap, no update."""
    tracker = make_tracker(c)
    e, out = start, []
    for t in t_gap:
        e = tracker.predict_from(e, float(t))
        out.append(e)
    return _trajectory(out)


def j2_coast(c: EstimatorConfig, real: Iterable[Measurement],
             t_gap: np.ndarray) -> ArmTrajectory | None:
    """Return the EKF of `c` with a two-body + J2 motion model, coasting through the gap.

    The filter runs with its process noise `J2_COAST_Q` over the real measurements before
    the gap; None unless `c` tracks an Earth orbit.
    """
    if c.filter.motion.motion_model not in ORBIT_MODELS:
        return None
    j2 = c.with_(filter=c.filter.with_(motion_model=MotionModel.J2, q=J2_COAST_Q))
    before = [m for m in real if m.t < t_gap[0] and m.source == Source.SENSOR]
    return coast(j2, start_estimate(run_filter(j2, before), float(t_gap[0])), t_gap)


def batch_fit(c: EstimatorConfig, real: Sequence[Measurement], start: StateEstimate,
              t_gap: np.ndarray) -> ArmTrajectory | None:
    """Return the batch least-squares fit over the last passes, predicted through the gap.

    See the module docstring. `real` in epoch order; `start` (the filter's estimate at its
    last real measurement before the gap) is the first guess. None unless `c` tracks an Earth
    orbit with measurements a batch fit models, or when the fit diverges or is
    underdetermined (then no engineer would have an orbit either).
    """
    if c.filter.motion.motion_model not in ORBIT_MODELS:
        return None
    sensor = [m for m in real if m.source == Source.SENSOR]
    window = gap_window().select(sensor, float(t_gap[0]))
    fit = fit_passes(window, measurement_model(c), start.x, start.t,
                     (c.jd0 - UNIX_EPOCH_JD) * DAY_S)
    if fit is None:
        return None
    x, P = fit.predict(t_gap)
    return ArmTrajectory(np.asarray(t_gap, float), x, P,
                         np.full(len(t_gap), UpdateSource.NONE))


class _Epochs:
    """A filter's estimates by epoch, looked up up to round-off (`types.same_epoch`)."""

    def __init__(self, estimates: Mapping[float, StateEstimate]) -> None:
        self.times = sorted(estimates)
        self.estimates = estimates

    def at(self, t: float) -> StateEstimate | None:
        """Return the estimate at epoch t, or None."""
        k = bisect.bisect_left(self.times, t)
        for j in (k - 1, k):
            if 0 <= j < len(self.times) and same_epoch(self.times[j], t):
                return self.estimates[self.times[j]]
        return None

    def before(self, t: float) -> StateEstimate | None:
        """Return the last estimate before epoch t (not at it), or None."""
        k = bisect.bisect_left(self.times, t)
        while k > 0 and same_epoch(self.times[k - 1], t):
            k -= 1
        return self.estimates[self.times[k - 1]] if k > 0 else None


def at_epochs(c: EstimatorConfig, estimates: Mapping[float, StateEstimate],
              t_gap: np.ndarray) -> ArmTrajectory:
    """Return a filter's estimate at each gap epoch, else its prediction there.

    The prediction (`Tracker.predict_from`, with the EKF of `c`) goes from the previous
    epoch's output when no estimate came between (chained, as a filter publishing at a
    cadence through a gap does), else from the last estimate before it.
    """
    tracker = make_tracker(c)
    lookup = _Epochs(estimates)
    out: list[StateEstimate] = []
    for t in t_gap:
        e = lookup.at(float(t))
        if e is None:
            prev = lookup.before(float(t))
            if prev is None:
                raise ValueError(f"no estimate before gap epoch t={t}")
            if out and out[-1].t >= prev.t:
                prev = out[-1]  # nothing new since the last output: go on from it
            e = tracker.predict_from(prev, float(t))
        out.append(e)
    return _trajectory(out)


def dmd_ekf(c: EstimatorConfig, estimates: Mapping[float, StateEstimate],
            t_gap: np.ndarray) -> ArmTrajectory:
    """Return the filter's estimates fusing the surrogate's forecasts (`at_epochs`)."""
    return at_epochs(c, estimates, t_gap)


def hypothetical(c: EstimatorConfig, real_and_withheld: Iterable[Measurement],
                 t_gap: np.ndarray) -> ArmTrajectory:
    """Return the EKF of `c` over the real measurements and the gap's withheld ones.

    `at_epochs`: an epoch whose measurement the filter rejected carries its prediction.
    """
    return at_epochs(c, run_filter(c, real_and_withheld), t_gap)


@dataclass
class GapEvaluation:
    """Every arm over one gap, scored.

    t : (k,) gap epochs; truth : (k, n); arms / scores by `ArmName` (j2_coast and batch_fit absent
    where they do not apply); coverage : fraction of gap epochs with a filter estimate that fused a
    forecast; predicted : gap epochs where dmd_ekf is the filter's prediction.
    """

    t: np.ndarray
    truth: np.ndarray
    arms: dict[ArmName, ArmTrajectory]
    scores: dict[ArmName, ArmScore]
    coverage: float
    predicted: int


def evaluate_gap(c: EstimatorConfig, estimates: Mapping[float, StateEstimate],
                 real: list[Measurement], withheld: list[Measurement], t_gap: np.ndarray,
                 x_true: np.ndarray, seed: int,
                 only: Iterable[ArmName] = tuple(ArmName)) -> GapEvaluation:
    """Score the arms over the gap `t_gap` with true states `x_true` (all, or those in `only`).

    `estimates`: the filter's estimates fusing the surrogate's forecasts (live from a bag, or
    offline), last per epoch; `real`: the real measurements (not the gap's); `withheld`: the
    gap's measurements; `seed`: the placeholder's Monte Carlo draws.
    """
    t_gap = np.asarray(t_gap, dtype=float)
    wanted = set(only)
    start = start_estimate(estimates, float(t_gap[0]))
    arms: dict[ArmName, ArmTrajectory] = {}
    if ArmName.PLACEHOLDER in wanted:
        arms[ArmName.PLACEHOLDER] = placeholder(c, start, t_gap, seed)
    if ArmName.COAST in wanted:
        arms[ArmName.COAST] = coast(c, start, t_gap)
    j2 = j2_coast(c, real, t_gap) if ArmName.J2_COAST in wanted else None
    if j2 is not None:
        arms[ArmName.J2_COAST] = j2
    fitted = batch_fit(c, real, start, t_gap) if ArmName.BATCH_FIT in wanted else None
    if fitted is not None:
        arms[ArmName.BATCH_FIT] = fitted
    if ArmName.DMD_EKF in wanted:
        arms[ArmName.DMD_EKF] = dmd_ekf(c, estimates, t_gap)
    if ArmName.HYPOTHETICAL_EKF in wanted:
        arms[ArmName.HYPOTHETICAL_EKF] = hypothetical(c, [*real, *withheld], t_gap)
    scores = {name: score(arm, x_true) for name, arm in arms.items()}
    lookup = _Epochs(estimates)
    found = [lookup.at(float(t)) for t in t_gap]
    fused = [e is not None and e.update_source == UpdateSource.FORECAST for e in found]
    predicted = sum(e is None for e in found)
    return GapEvaluation(t_gap, x_true, arms, scores, float(np.mean(fused)), predicted)
