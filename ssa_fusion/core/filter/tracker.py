"""The estimator of one object: initial orbit determination, then an EKF.

The EKF runs over a stream of real and forecast measurements, with the input rules users
rely on.

`Tracker.process(m)` takes measurements in arrival order and returns what happened: an
estimate (state + covariance at the measurement epoch) or the cause of a rejection. The
tracker is the facade over two parts: until its EKF exists, the measurements it admits go to
`initiation.OrbitInitiator` (the initial orbit determination, with its own rules during IOD);
after that, every fused step is logged in `history.FusedHistory`, which rolls the filter back
when a measurement goes in front of fused ones. The admission and arbitration rules are here
(the behaviour users rely on, README and docs/NODES.md):

* bad input is never fused (`validation.measurement_problem`, shared with the surrogate):
  non-finite values, negative range, elevation outside [-pi/2, pi/2], a kind or frame the
  tracker is not configured for, a covariance that is not symmetric positive semi-definite
  (to round-off), a negative forecast horizon, a stamp older than the last real
  measurement fused, a duplicate epoch, or an innovation beyond the NIS gate;
* a second station's measurement at the epoch of the last real one is fused after it; the
  same station's again is a duplicate;
* a real measurement always beats a forecast for the same epoch: a forecast for an epoch
  that already has a real measurement is dropped, and a real measurement for an epoch at or
  before fused forecasts rolls them back, fuses the real one and re-fuses the later forecasts
  whose model already knew it;
* the newest model wins: a forecast's model ended at its *base* epoch ``t - horizon`` (the
  last real measurement it was trained on). A forecast whose model ended before the last
  real measurement preceding its epoch is dropped, and a forecast for an epoch at or before
  fused forecasts of an older model rolls those back and replaces them. The surrogate
  re-forecasts every missed epoch after each real measurement, so a forecast issued while a
  real measurement was still on its way (a surrogate stalled by a fit at a high time scale)
  is replaced, and the result equals the offline replay's;
* late forecasts still count: a valid forecast for an epoch inside the filter's history (the
  steps fused since `HISTORY_REAL` real measurements back, `history`) with nothing fused at
  it yet (typically a gap's last forecasts, which the surrogate releases when the
  measurement ending the gap reaches it, on another topic) is fused at its epoch, with
  everything fused after it fused again. So the final state, and the last estimate published
  per epoch, do not depend on the order in which forecasts and the real measurements after
  them arrive (real measurements themselves must arrive in order); the exception is a real
  measurement that passes the gate on one state and not on the other (its earlier estimate
  then stays published);
* a filter that has lost its object re-initialises: after ``reinit_after`` real
  measurements in a row refused by the gate (a whole pass that disagrees with the
  prediction, typically after a gap longer than the process noise allows for), it forgets its
  state and starts a new IOD batch with the last of them (`Cause.REINITIALISED`);
* `reset()` forgets everything (a backwards clock jump);
* a tracker given an a-priori orbit (`set_prior`: a prediction, such as the CPF a laser
  station points with) starts its EKF from it at the first real measurement it takes,
  instead of an IOD batch: laser ranges alone give no initial orbit.

The state may hold more than the orbit (a laser filter's range biases and k_R after
``[r, v]``): the white-noise acceleration of the process noise acts on the first
``dynamic`` states only, the others are constants to the noise.

It is the same code live (filter node) and offline (reproduce, replay), so both give the
same estimates for the same input sequence.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ssa_fusion.core.base.types import (
    Cause,
    Measurement,
    Source,
    StateEstimate,
    UpdateSource,
    same_epoch,
)
from ssa_fusion.core.filter.ekf import ExtendedKalmanFilter, bound_covariance, process_noise
from ssa_fusion.core.filter.history import HISTORY_REAL, FusedHistory, FusedStep, Snapshot
from ssa_fusion.core.filter.initiation import OrbitInitiator, Placeholder
from ssa_fusion.core.filter.options import FilterOptions
from ssa_fusion.core.measure.laser_model import LaserModels, LaserStationModel
from ssa_fusion.core.measure.measurement import MeasurementModel, StationModels
from ssa_fusion.core.measure.validation import OK, measurement_problem


def _base(f: Measurement) -> float:
    """Epoch of the last real measurement a forecast's model was trained on."""
    return f.t - f.horizon


def _before(a: float, b: float) -> bool:
    """Return a < b beyond the round-off of t - horizon (`types.same_epoch`)."""
    return a < b and not same_epoch(a, b)


def prediction_epochs(after: float, now: float, period: float,
                      limit: int) -> tuple[list[float], int]:
    """Return the epochs (s) where a filter publishing every `period` s of sim time predicts.

    They are the multiples of `period` in (`after`, `now`], at most `limit` of them, the
    earliest first (a caller catches up over later calls); returns (epochs, skipped), where
    `skipped` counts the earliest ones left out when more than `limit` * 10 are due (a clock
    that jumped far ahead: publishing them all would stall the caller).

    >>> prediction_epochs(100.0, 250.0, 60.0, 10)
    ([120.0, 180.0, 240.0], 0)
    """
    if not (period > 0.0 and math.isfinite(after) and math.isfinite(now)) or now <= after:
        return [], 0
    k0, k1 = math.floor(after / period) + 1, math.floor(now / period)
    skipped = max(0, (k1 - k0 + 1) - 10 * limit)
    k0 += skipped
    return [k * period for k in range(k0, min(k1, k0 + limit - 1) + 1)], skipped


@dataclass
class Outcome:
    """What `Tracker.process` did with one measurement.

    Attributes
    ----------
    estimate : StateEstimate or None
        The estimate at the measurement epoch when it was fused.
    rejected, detail : str
        Otherwise the cause (a key) and a sentence for the log.
    rolled_back : int
        Fused forecasts undone to put this measurement in front of them.
    fused_again : list of StateEstimate
        Estimates of the measurements (forecasts, and real ones after a late forecast)
        fused again after it, also when it was itself rejected: they are new estimates all
        the same.
    """

    estimate: StateEstimate | None = None
    rejected: str = ""
    detail: str = ""
    rolled_back: int = 0
    fused_again: list[StateEstimate] = field(default_factory=list)


class Tracker:
    """IOD + EKF for one object (see the module docstring for the rules).

    ``config`` (`filter_options.FilterOptions`: its noise and IOD parts; the motion model
    is ``placeholder``) may be replaced at run time; ``f``, ``model`` and ``n`` are handed
    to the `initiation.OrbitInitiator` at construction and at each `reset`. ``frame_id``
    is the frame (station id, or "gcrf") measurements must be expressed in; "" = any (with
    a station network: any of its stations). ``dynamic`` (default ``n``): the leading
    ``[pos, vel]`` states the process noise acts on.
    """

    def __init__(self, placeholder: Placeholder, model: MeasurementModel,
                 config: FilterOptions, n: int = 6, object_id: str = "",
                 frame_id: str = "", dynamic: int | None = None) -> None:
        self.f = placeholder
        self.model = model
        self.kind = model.kind
        self.config = config
        self.n = n
        self.dynamic = n if dynamic is None else int(dynamic)
        self.object_id = object_id
        self.frame_id = frame_id
        self.prior: StateEstimate | None = None
        self.reset()

    def set_prior(self, e: StateEstimate) -> None:
        """Start the EKF from the a-priori estimate ``e`` (of size n) at the first measurement.

        Not from an IOD batch (module docstring); before initialisation only.
        """
        if len(e.x) != self.n or np.shape(e.P) != (self.n, self.n):
            raise ValueError(f"an a-priori state of {len(e.x)} for a filter of {self.n}")
        self.prior = StateEstimate(float(e.t), np.array(e.x, dtype=float),
                                   np.array(e.P, dtype=float), self.object_id)

    # ----------------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget the state and every buffered measurement (a new IOD batch starts)."""
        self.ekf: ExtendedKalmanFilter | None = None
        self.t = -math.inf
        self.t_real = -math.inf
        self._initiator = OrbitInitiator(self.f, self.model, self.n)
        self._gate_misses = 0  # real measurements refused by the gate in a row
        self._iod_end = (-math.inf, "")  # epoch and frame of the IOD batch's last measurement
        # the steps fused since `HISTORY_REAL` real measurements back, oldest first
        self._history = FusedHistory(HISTORY_REAL)

    @property
    def initialised(self) -> bool:
        """True once the initial orbit determination has started the EKF."""
        return self.ekf is not None

    def estimate(self, source: int = 0, nis: float = 0.0) -> StateEstimate:
        """Return the current estimate (copies of x, P at epoch `t`), tagged `source`, `nis`.

        Only after initialisation (AssertionError before).
        """
        assert self.ekf is not None
        return StateEstimate(self.t, self.ekf.x.copy(), self.ekf.P.copy(), self.object_id,
                             source, nis)

    def predicted(self, t: float) -> StateEstimate | None:
        """Prediction to epoch `t` (no state change), or None before IOD or for t < epoch."""
        if self.ekf is None or t < self.t:
            return None
        return self.predict_from(StateEstimate(self.t, self.ekf.x, self.ekf.P, self.object_id), t)

    def predict_from(self, e: StateEstimate, t: float) -> StateEstimate:
        """Predict estimate `e` to epoch `t` (s) with this tracker's model and process noise.

        x by the placeholder model, P = F P F^T + Q; the tracker is not changed.
        """
        x, F = self.f(e.x, t - e.t, e.t)
        P = F @ e.P @ F.T + self._Q(t - e.t)
        P = bound_covariance(x, 0.5 * (P + P.T), self.config.noise.sigma_bound)
        return StateEstimate(t, x, P, e.object_id, 0, 0.0)

    def restart_from(self, e: StateEstimate) -> None:
        """Go on from estimate `e` (epoch, state, covariance) instead of the EKF's own state.

        The sequential update starts again from a prior made elsewhere (a batch fit's
        prediction to the first measurement of a pass, `gap_publisher.GapFill.BATCH_INIT`).
        The fused history is forgotten: nothing before `e.t` is rolled back or fused again,
        a forecast for an earlier epoch is refused as older than the history; the last real
        epoch and the count of real measurements refused by the gate in a row stay (the
        input rules and the re-initialisation still hold). Only after initialisation, with `e.t` at
        or after the last real measurement fused (AssertionError otherwise).
        """
        assert self.ekf is not None and e.t >= self.t_real
        self.ekf.restore(e.x, e.P)
        self.t = float(e.t)
        self._history = FusedHistory(HISTORY_REAL)

    # ----------------------------------------------------------------------------------
    def process(self, m: Measurement) -> Outcome:
        """Validate and fuse one measurement (real or forecast); see module docstring."""
        cause, detail = self._validate(m)
        if cause:
            return Outcome(rejected=cause, detail=detail)
        if self.ekf is None:
            return self._initialise(m)
        if m.source == Source.FORECAST:
            return self._fuse_forecast(m)
        out = self._fuse_real(m)
        if out.rejected != Cause.REJECTED_GATE:
            self._gate_misses = 0 if out.estimate is not None else self._gate_misses
            return out
        self._gate_misses += 1
        limit = self.config.iod.reinit_after
        if not limit or self._gate_misses < limit:
            return out
        self.reset()
        self._initialise(m)
        return Outcome(rejected=Cause.REINITIALISED,
                       detail=f"{limit} real measurements in a row beyond the gate "
                              f"(last: {out.detail}): the filter lost its object; initial "
                              f"orbit determination starts again at t={m.t}")

    def _validate(self, m: Measurement) -> tuple[str, str]:
        if m.source not in (Source.SENSOR, Source.FORECAST):
            return Cause.REJECTED_SOURCE, f"unknown source {m.source}"
        problem = measurement_problem(m, self.kind, self.frame_id)
        if problem == OK and m.horizon < 0.0:
            return Cause.REJECTED_HORIZON, f"forecast horizon {m.horizon} s < 0 at t={m.t}"
        if (problem == OK and isinstance(self.model, StationModels | LaserModels)
                and self.model.get(m.kind, m.frame_id) is None):
            return (Cause.REJECTED_FRAME, f"station {m.frame_id!r} is not in the network "
                                          f"({', '.join(self.model.stations)})")
        return problem

    def _model_for(self, m: Measurement) -> MeasurementModel | LaserStationModel:
        """Return the model that predicts `m` (its station's, for a network)."""
        if isinstance(self.model, StationModels | LaserModels):
            model = self.model.get(m.kind, m.frame_id)
            assert model is not None  # validated
            return model
        return self.model

    def process_noise(self, dt: float) -> np.ndarray:
        """Return the process noise (n, n) of a prediction over ``dt`` s (module docstring)."""
        d = self.dynamic
        q = process_noise(abs(dt), self.config.noise.q, dim=d // 2)
        if d == self.n:
            return q
        out = np.zeros((self.n, self.n))
        out[:d, :d] = q
        return out

    def _Q(self, dt: float) -> np.ndarray:
        return self.process_noise(dt)

    def _step(self, m: Measurement, source: int) -> Outcome:
        """Predict to m.t and update with m (the EKF exists).

        Numerically hopeless input (overflowing values) is rejected with the state left as
        it was.
        """
        ekf = self.ekf
        assert ekf is not None
        dt = m.t - self.t
        before = Snapshot(self.t, ekf.x, ekf.P)
        model, t = self._model_for(m), m.t
        assert not isinstance(model, StationModels | LaserModels)
        noise = self.config.noise
        try:
            with np.errstate(over="raise", invalid="raise"):
                if dt != 0.0:
                    ekf.predict(lambda x: self.f(x, dt, before.t), self._Q(dt))
                    if noise.sigma_bound:
                        ekf.P = bound_covariance(ekf.x, ekf.P, noise.sigma_bound)
                        ekf.P_prior = ekf.P.copy()
                result = ekf.update(m.z, lambda x: model.h_and_H(x, t), m.R,
                                    model.angle_mask, noise.gate)
            ok: bool | np.bool_ = np.isfinite(ekf.x).all() and np.isfinite(ekf.P).all()
        except (ValueError, OverflowError, FloatingPointError, np.linalg.LinAlgError) as exc:
            ok, result, reason = False, None, f"{type(exc).__name__}: {exc}"
        if not ok:
            self.t = before.t
            ekf.restore(before.x, before.P)
            return Outcome(rejected=Cause.REJECTED_NUMERIC,
                           detail=f"t={m.t}: update not computable "
                                  f"({reason if result is None else 'non-finite state'})")
        assert result is not None  # ok: the update ran
        self.t = m.t
        if not result.accepted:
            return Outcome(rejected=Cause.REJECTED_GATE,
                           detail=f"NIS {result.nis:.1f} > gate {noise.gate}")
        return Outcome(estimate=self.estimate(source, result.nis))

    def _fuse_forecast(self, m: Measurement) -> Outcome:
        base = _base(m)
        k = self._history.position(m.t)
        at = self._history.at(k)  # None: after every fused step
        if at is not None and at.m.t == m.t and at.m.source != Source.FORECAST:
            return Outcome(rejected=Cause.FORECAST_SUPERSEDED,
                           detail=f"forecast for t={m.t}, which has a real measurement")
        if m.t <= self.t and (at is None or not at.before.t < m.t):
            first = self._history.at(0)
            return Outcome(rejected=Cause.FORECAST_SUPERSEDED,
                           detail=f"forecast for t={m.t} is older than the filter's history "
                                  f"(back to t={first.m.t if first else self.t})")
        t_prev = self.t_real if at is None else at.t_real  # the last real before m.t
        if _before(base, t_prev):
            return Outcome(rejected=Cause.FORECAST_SUPERSEDED,
                           detail=f"forecast for t={m.t} from a model that ended at t={base}, "
                                  f"before the real measurement at t={t_prev}")
        if at is not None and at.m.t == m.t and not _before(_base(at.m), base):
            return Outcome(rejected=Cause.REJECTED_STALE,
                           detail=f"forecast t={m.t}: a forecast of the same or a newer model "
                                  f"was fused for it")
        return self._insert(k, m, UpdateSource.FORECAST)

    def _fuse_real(self, m: Measurement) -> Outcome:
        if m.t < self.t_real:
            return Outcome(rejected=Cause.REJECTED_STALE,
                           detail=f"t={m.t} older than the last real measurement t={self.t_real}")
        if m.t == self.t_real:
            if m.frame_id in self._frames_at_real():
                return Outcome(rejected=Cause.REJECTED_DUPLICATE,
                               detail=f"second measurement at t={m.t} from {m.frame_id!r}")
            # another station at the same epoch: fused after the ones already fused
            return self._insert(self._history.position_after(m.t), m, UpdateSource.SENSOR)
        return self._insert(self._history.position(m.t), m, UpdateSource.SENSOR)

    def _frames_at_real(self) -> set[str]:
        """Return the frames (stations) of the real measurements fused at ``t_real``."""
        frames = {e.m.frame_id for e in self._history.steps
                  if e.m.t == self.t_real and e.m.source != Source.FORECAST}
        if self.t_real == self._iod_end[0]:
            frames.add(self._iod_end[1])
        return frames

    def _insert(self, k: int, m: Measurement, source: int) -> Outcome:
        """Undo the fused steps from index k on (epochs at or after m.t), fuse m, fuse again.

        Fused again are every real measurement after m.t, and every forecast after m.t
        whose model knew what m says (a real m: trained on it; a forecast m: a model no
        older than m's). The dropped forecasts wait for the surrogate's newer ones. That
        holds even if m itself is rejected (the surrogate has buffered it all the same), so
        the filter ends as in the offline order; `fused_again` then still lists them.
        """
        tail = self._rollback(k) if k < len(self._history) else []
        out = self._fuse_step(m, source)
        base = m.t if source == UpdateSource.SENSOR else _base(m)
        out.rolled_back = sum(e.m.source == Source.FORECAST for e in tail)
        for e in tail:
            if e.m.t <= m.t or (e.m.source == Source.FORECAST and _before(_base(e.m), base)):
                continue
            # it was valid before; only the gate can refuse it now
            again = self._fuse_step(e.m, UpdateSource.FORECAST if e.m.source == Source.FORECAST
                                    else UpdateSource.SENSOR)
            if again.estimate is not None:
                out.fused_again.append(again.estimate)
        return out

    def _fuse_step(self, m: Measurement, source: int) -> Outcome:
        """`_step`, logged when fused; the state is left unchanged when it is not."""
        assert self.ekf is not None
        before = Snapshot(self.t, *self.ekf.snapshot())
        t_real = self.t_real
        out = self._step(m, source)
        if out.estimate is None:
            self._restore(before)
        else:
            self._append(FusedStep(m, before, t_real))
        return out

    def _append(self, e: FusedStep) -> None:
        """Log a fused step; a real one also advances t_real (and trims the history)."""
        self._history.record(e)
        if e.m.source != Source.FORECAST:
            self.t_real = e.m.t

    def _rollback(self, k: int) -> list[FusedStep]:
        """Back to the state before the k-th fused step; return the steps from k on, forgotten."""
        assert self.ekf is not None
        tail = self._history.rollback(k, self.ekf)
        self.t, self.t_real = tail[0].before.t, tail[0].t_real
        return tail

    def _restore(self, s: Snapshot) -> None:
        """Set the epoch and the EKF's x, P back to (copies of) a snapshot."""
        assert self.ekf is not None
        self.t = s.t
        self.ekf.restore(s.x, s.P)

    # ----------------------------------------------------------------------------------
    def _initialise(self, m: Measurement) -> Outcome:
        """Hand `m` to the IOD batch; start the EKF when it is solved (or from `set_prior`)."""
        if self.prior is not None and m.source != Source.FORECAST:
            self.ekf = ExtendedKalmanFilter(self.prior.x, self.prior.P)
            self.t = self.prior.t
            return self._fuse_real(m)
        if isinstance(self.model, LaserModels):
            return Outcome(rejected=Cause.IOD_PENDING,
                           detail="laser ranges alone give no initial orbit: waiting for an "
                                  "a-priori orbit")
        iod = self.config.iod
        got = self._initiator.add(m, iod.iod_samples, iod.p0_sigma, iod.iod_max_span_s)
        if isinstance(got, tuple):
            cause, detail = got
            return Outcome(rejected=cause, detail=detail)
        self.ekf = ExtendedKalmanFilter(got.x, got.P)
        self.t = self.t_real = got.t
        self._iod_end = (got.t, m.frame_id)
        return Outcome(estimate=self.estimate(UpdateSource.SENSOR))
