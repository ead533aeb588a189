"""The estimator of one object: initial orbit determination, then an EKF.

The EKF runs over a stream of real and forecast measurements, with the input rules users
rely on.

`Tracker.process(m)` takes measurements in arrival order and returns what happened: an
estimate (state + covariance at the measurement epoch) or the cause of a rejection. The
rules (DESIGN.md "Behaviour users rely on"):

* bad input is never fused (`validation.measurement_problem`, shared with the surrogate):
  non-finite values, negative range, elevation outside [-pi/2, pi/2], a kind or frame the
  tracker is not configured for, a covariance that is not symmetric positive semi-definite
  (to round-off), a negative forecast horizon, a stamp older than the last real
  measurement fused, a duplicate epoch, or an innovation beyond the NIS gate;
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
* late forecasts still count: the filter keeps what it fused since `HISTORY_REAL` real
  measurements back, and a valid forecast for an epoch inside that history with nothing
  fused at it yet (typically a gap's last forecasts, which the surrogate releases when the
  measurement ending the gap reaches it, on another topic) is fused at its epoch, with
  everything fused after it fused again. So the final state, and the last estimate published
  per epoch, do not depend on the order in which forecasts and the real measurements after
  them arrive (real measurements themselves must arrive in order); the exception is a real
  measurement that passes the gate on one state and not on the other (its earlier estimate
  then stays published);
* `reset()` forgets everything (a backwards clock jump).

It is the same code live (filter node) and offline (reproduce, replay), so both give the
same estimates for the same input sequence.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import cast

import numpy as np

from . import iod
from .ekf import ExtendedKalmanFilter, process_noise
from .measurement import PositionModel, RazelModel
from .types import Cause, Kind, Measurement, Source, StateEstimate, UpdateSource
from .validation import OK, measurement_problem

Placeholder = Callable[[np.ndarray, float], tuple[np.ndarray, np.ndarray]]


def _base(f: Measurement) -> float:
    """Epoch of the last real measurement a forecast's model was trained on."""
    return f.t - f.horizon


def _before(a: float, b: float) -> bool:
    """Return a < b beyond the round-off of t - horizon (~1e-16 relative; 2 ms on Unix time)."""
    return a < b - 1e-12 * max(1.0, abs(b))


DEFAULT_GATE = 1000.0
"""Default NIS gate: rejects gross glitches only (a 3-channel innovation ~30 sigma away)."""


@dataclass
class TrackerConfig:
    """Estimator settings.

    Attributes
    ----------
    p0_sigma : tuple of float, (n,)
        Standard deviations added (in quadrature) to the IOD covariance, state units.
    q : float
        White-noise acceleration spectral density of the process noise, (units/s^2)^2 s.
    gate : float or None
        NIS threshold beyond which an update is rejected (None: no gate; the default
        only catches gross glitches, the estimate's consistency is not gated away).
    iod_samples : int
        Real measurements used for the initial orbit determination (>= 2; 3 for
        Herrick-Gibbs with range/az/el).
    frame_id : str
        Frame (station id, or "eci") measurements must be expressed in; "" = any.
    """

    p0_sigma: tuple[float, ...] = (1.0, 1.0, 1.0, 1e-3, 1e-3, 1e-3)
    q: float = 1e-10
    gate: float | None = DEFAULT_GATE
    iod_samples: int = 3
    frame_id: str = ""


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


@dataclass
class _Snapshot:
    t: float
    x: np.ndarray
    P: np.ndarray


@dataclass
class _Fused:
    """A measurement the filter fused, the state before it and the last real epoch then."""

    m: Measurement
    before: _Snapshot
    t_real: float


HISTORY_REAL = 8
"""Real measurements back to which the filter keeps its fused steps, so that a forecast that
arrives after the real measurements that followed its epoch (a gap's last forecasts, which the
surrogate releases when the measurement ending the gap reaches it) can still go in front of
them; 8 cadences are 0.24 s of wall time at 1000x real time."""


class Tracker:
    """IOD + EKF for one object (see the module docstring for the rules)."""

    def __init__(self, placeholder: Placeholder, model: PositionModel | RazelModel,
                 config: TrackerConfig, n: int = 6, object_id: str = "") -> None:
        self.f = placeholder
        self.model = model
        self.config = config
        self.n = n
        self.object_id = object_id
        self.kind = model.kind
        self.reset()

    # ----------------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget the state and every buffered measurement."""
        self.ekf: ExtendedKalmanFilter | None = None
        self.t = -math.inf
        self.t_real = -math.inf
        self._iod: list[Measurement] = []
        # the steps fused since `HISTORY_REAL` real measurements back, oldest first
        self._log: list[_Fused] = []

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
        x, F = self.f(e.x, t - e.t)
        P = F @ e.P @ F.T + self._Q(t - e.t)
        return StateEstimate(t, x, 0.5 * (P + P.T), e.object_id, 0, 0.0)

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
        return self._fuse_real(m)

    def _validate(self, m: Measurement) -> tuple[str, str]:
        if m.source not in (Source.SENSOR, Source.FORECAST):
            return Cause.REJECTED_SOURCE, f"unknown source {m.source}"
        problem = measurement_problem(m, self.kind, self.config.frame_id)
        if problem == OK and m.horizon < 0.0:
            return Cause.REJECTED_HORIZON, f"forecast horizon {m.horizon} s < 0 at t={m.t}"
        return problem

    def _Q(self, dt: float) -> np.ndarray:
        return process_noise(abs(dt), self.config.q, dim=self.n // 2)

    def _step(self, m: Measurement, source: int) -> Outcome:
        """Predict to m.t and update with m (the EKF exists).

        Numerically hopeless input (overflowing values) is rejected with the state left as
        it was.
        """
        ekf = self.ekf
        assert ekf is not None
        dt = m.t - self.t
        before = _Snapshot(self.t, ekf.x, ekf.P)
        model, t = self.model, m.t
        try:
            with np.errstate(over="raise", invalid="raise"):
                if dt != 0.0:
                    ekf.predict(lambda x: self.f(x, dt), self._Q(dt))
                result = ekf.update(m.z, lambda x: model.h_and_H(x, t), m.R,
                                    model.angle_mask, self.config.gate)
            ok: bool | np.bool_ = np.isfinite(ekf.x).all() and np.isfinite(ekf.P).all()
        except (ValueError, OverflowError, FloatingPointError, np.linalg.LinAlgError) as exc:
            ok, result, reason = False, None, f"{type(exc).__name__}: {exc}"
        if not ok:
            self.t, ekf.x, ekf.P = before.t, before.x, before.P
            return Outcome(rejected=Cause.REJECTED_NUMERIC,
                           detail=f"t={m.t}: update not computable "
                                  f"({reason if result is None else 'non-finite state'})")
        assert result is not None  # ok: the update ran
        self.t = m.t
        if not result.accepted:
            return Outcome(rejected=Cause.REJECTED_GATE,
                           detail=f"NIS {result.nis:.1f} > gate {self.config.gate}")
        return Outcome(estimate=self.estimate(source, result.nis))

    def _fuse_forecast(self, m: Measurement) -> Outcome:
        base = _base(m)
        k = self._position(m.t)
        at = self._log[k] if k < len(self._log) else None  # None: after every fused step
        if at is not None and at.m.t == m.t and at.m.source != Source.FORECAST:
            return Outcome(rejected=Cause.FORECAST_SUPERSEDED,
                           detail=f"forecast for t={m.t}, which has a real measurement")
        if m.t <= self.t and (at is None or not at.before.t < m.t):
            return Outcome(rejected=Cause.FORECAST_SUPERSEDED,
                           detail=f"forecast for t={m.t} is older than the filter's history "
                                  f"(back to t={self._log[0].m.t if self._log else self.t})")
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
            return Outcome(rejected=Cause.REJECTED_DUPLICATE,
                           detail=f"second measurement at t={m.t}")
        return self._insert(self._position(m.t), m, UpdateSource.SENSOR)

    def _position(self, t: float) -> int:
        """Index of the first fused step at or after epoch t (len(log) if none)."""
        return bisect.bisect_left([e.m.t for e in self._log], t)

    def _insert(self, k: int, m: Measurement, source: int) -> Outcome:
        """Undo the fused steps from index k on (epochs at or after m.t), fuse m, fuse again.

        Fused again are every real measurement after m.t, and every forecast after m.t
        whose model knew what m says (a real m: trained on it; a forecast m: a model no
        older than m's). The dropped forecasts wait for the surrogate's newer ones. That
        holds even if m itself is rejected (the surrogate has buffered it all the same), so
        the filter ends as in the offline order; `fused_again` then still lists them.
        """
        tail = self._log[k:]
        if tail:
            self._rollback(k)
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
        before = _Snapshot(self.t, self.ekf.x.copy(), self.ekf.P.copy())
        t_real = self.t_real
        out = self._step(m, source)
        if out.estimate is None:
            self._restore(before)
        else:
            self._append(_Fused(m, before, t_real))
        return out

    def _append(self, e: _Fused) -> None:
        """Log a fused step; a real one also advances t_real and trims the history.

        The history kept starts `HISTORY_REAL` real measurements back.
        """
        self._log.append(e)
        if e.m.source == Source.FORECAST:
            return
        self.t_real = e.m.t
        reals = [i for i, f in enumerate(self._log) if f.m.source != Source.FORECAST]
        if len(reals) > HISTORY_REAL:
            del self._log[:reals[-HISTORY_REAL]]

    def _rollback(self, k: int) -> None:
        """Back to the state before the k-th fused step; the steps from k on are forgotten."""
        e = self._log[k]
        self._restore(e.before)
        self.t_real = e.t_real
        del self._log[k:]

    def _restore(self, s: _Snapshot) -> None:
        """Set the epoch and the EKF's x, P back to (copies of) a snapshot."""
        assert self.ekf is not None
        self.t = s.t
        self.ekf.x, self.ekf.P = s.x.copy(), s.P.copy()

    # ----------------------------------------------------------------------------------
    def _initialise(self, m: Measurement) -> Outcome:
        if m.source == Source.FORECAST:
            return Outcome(rejected=Cause.IGNORED_BEFORE_IOD, detail="forecast before IOD")
        if self._iod and m.t <= self._iod[-1].t:
            return Outcome(rejected=Cause.REJECTED_STALE if m.t < self._iod[-1].t
                           else Cause.REJECTED_DUPLICATE, detail=f"t={m.t} during IOD")
        self._iod.append(m)
        if len(self._iod) < max(2, self.config.iod_samples):
            return Outcome(rejected=Cause.IOD_PENDING, detail="collecting IOD measurements")
        batch, self._iod = self._iod, []
        t_init, x0, P_iod = self._iod_solution(batch)
        if not np.isfinite(x0).all():
            return Outcome(rejected=Cause.IOD_FAILED, detail="initial orbit determination failed")
        t_last = batch[-1].t
        P0 = P_iod + np.diag(np.asarray(self.config.p0_sigma, dtype=float) ** 2)
        if t_last != t_init:  # Herrick-Gibbs solves at the middle epoch: move to the last
            x0, F = self.f(x0, t_last - t_init)
            P0 = F @ P0 @ F.T
        self.ekf = ExtendedKalmanFilter(x0, 0.5 * (P0 + P0.T))
        self.t = self.t_real = t_last
        return Outcome(estimate=self.estimate(UpdateSource.SENSOR))

    def _iod_solution(self, batch: list[Measurement]) -> tuple[float, np.ndarray, np.ndarray]:
        """Return (epoch, state, covariance) from the IOD batch.

        The covariance is the measurement noise pushed through the IOD map (numerical
        Jacobian, 1 evaluation per input).
        """
        t = np.array([b.t for b in batch])
        Z = np.array([b.z for b in batch], dtype=float)
        if self.kind == Kind.RANGE_AZ_EL:
            mid = len(batch) // 2
            i3 = [0, mid, len(batch) - 1]
            t3 = t[i3]
            razel = cast(RazelModel, self.model)  # the model of kind RANGE_AZ_EL

            def solve(zs: np.ndarray) -> np.ndarray:
                r = iod.razel_to_eci(zs[i3], razel.jd0_utc + t3 / 86400.0, razel.station)
                v2 = iod.herrick_gibbs(r[0], r[1], r[2], t3[0], t3[1], t3[2])
                return np.concatenate([r[1], v2])

            t_init = float(t3[1])
        else:
            observed = list(cast(PositionModel, self.model).observed)

            def solve(zs: np.ndarray) -> np.ndarray:
                x = np.zeros(self.n)
                fd = iod.finite_difference_state(t, zs)
                k = len(observed)
                x[observed] = fd[:k]
                x[[i + self.n // 2 for i in observed]] = fd[k:]
                return x

            t_init = float(t[-1])
        x0 = solve(Z)
        R = [np.asarray(b.R, dtype=float) for b in batch]
        P = np.zeros((self.n, self.n))
        for j, Rj in enumerate(R):
            sig = np.sqrt(np.clip(np.diag(Rj), 0.0, None))
            if not sig.any():
                continue
            J = np.zeros((self.n, Z.shape[1]))
            for c in range(Z.shape[1]):
                if sig[c] == 0.0:
                    continue
                dz = Z.copy()
                dz[j, c] += sig[c]
                J[:, c] = (solve(dz) - x0) / sig[c]
            P += J @ Rj @ J.T
        return t_init, x0, P
