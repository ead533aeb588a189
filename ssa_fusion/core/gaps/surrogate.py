"""The measurement surrogate: forecasts for the epochs the sensor missed.

A sliding buffer of real measurements, a Hankel-DMD model retrained on it, and forecasts
for the epochs the sensor missed.

`Surrogate.add(m)` takes real measurements; `Surrogate.due(now)` returns the forecasts that
have become due by sim time `now` (each missed epoch once). Which epochs get a forecast,
and its value, depend only on the measurements, never on when `due` is called: a gap is
the run of cadence epochs after the last real measurement, forecasts come from a model
trained on the buffer up to that measurement, and a real measurement that ends a gap first
releases the forecasts still owed for the epochs before it. This is what makes live runs
and offline replays give the same forecasts.

When a real measurement ends a gap, the gap's epochs are filled in the buffer with the
forecasts issued for them (`_fill_gap`), so the next fit still sees a regular window: with
372 delays a fit needs 746 regular samples (6.2 h at 30 s), and without the fill a second
outage within that time would get no forecasts at all.

Each forecast carries the covariance Var(e(h)) of paper section 4 (Var(e) = R + A E[zz^T] A^T):
the in-sample error of h-step forecasts against the *measured* samples, so it already
contains the sensor noise R once; it is floored at R (PSD sense) and grows with h.

Noisy channels are whitened (`SurrogateConfig.whiten`): each is divided by its known noise
sigma before the fit and the forecasts and covariances are scaled back, so that the noise
is i.i.d. across channels as the automatic rank threshold (Gavish-Donoho) assumes. Without
it a channel with a large offset (CR3BP x, noise 1 % of its RMS ~ 10x the others') sets
the threshold and the other channels are fitted into their noise.

Optionally (`SurrogateConfig.lift`) the DMD learns a *lifted* observable instead of the raw
measurement: for range/az/el from a known station, `EciLift` turns each measurement into the
GCRF position it implies (station position + line of sight, no dynamics), Hankel-DMD learns
and forecasts that (nearly linear, like the position scenarios), and each forecast is mapped
back to range/az/el. Its covariance is measured in range/az/el too: the in-sample lifted
predictions are mapped back at their own epochs and compared with what the sensor measured
(`EciLift.residual`). The filter still receives range/az/el forecasts.

Correlation (`SurrogateConfig.inflate_correlated`, default on): all forecasts of one gap come
from one model fitted on one buffer, so their model errors are nearly the same systematic
error, not independent draws. Fused as independent measurements, k of them would shrink the
filter's covariance k-fold while the error stays (NEES of hundreds). Of Var(e(k)) = R + D(k)
(sensor noise R, model part D(k) >= 0), only D is that common error: the in-sample noise R is
independent from epoch to epoch. The k-th forecast after the last real measurement therefore
carries R + k * D(k) (`correlation_power` p gives R + k^p * D(k); p = 1 by default): the
filter's covariance grows through the gap as far as the model error says, while a forecast
whose model error is small against R still counts as much as the measurement it replaces.
Scaling all of Var(e(k)) by k instead would discount R too: iss_j2_rae forecasts, 2-7x
better than the sensor in angle, would be fused as if 14-20x worse at the end of the gap.
The alternatives measured (p = 2, a random-walk bias state in the EKF) are in
docs/HISTORY.md.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ssa_fusion.core.base.types import Cause, Kind, Measurement, Source
from ssa_fusion.core.earth.frames import razel_gcrs, wrap_pi
from ssa_fusion.core.gaps.hankel_dmd import HankelDMD, psd_part
from ssa_fusion.core.measure.iod import razel_to_gcrs
from ssa_fusion.core.measure.measurement import RazelModel
from ssa_fusion.core.measure.validation import OK, Problem, measurement_problem, razel_possible


@dataclass
class SurrogateConfig:
    """Settings of a `Surrogate` (times in sim seconds).

    Attributes
    ----------
    buffer_s : float
        Length of the sliding training buffer, s.
    retrain_period_s : float
        Refit at least this often (sim s) while measurements arrive (inf: never); a gap
        always starts from a model fitted up to the last real measurement.
    delays, rank : int, int or None
        Hankel-DMD settings (rank None: automatic).
    max_horizon_s : float
        No forecast beyond this many s after the last real measurement.
    cadence_s : float
        Expected measurement interval, s (0: inferred from the last `CADENCE_SAMPLES`
        intervals in the buffer, see `Surrogate._infer_cadence`).
    grace : float
        Fraction of a cadence after an epoch before it counts as missed.
    jitter : float
        Largest deviation of a sampling interval from the cadence, as a fraction of the
        cadence, that still counts as the cadence (stamp jitter; such samples are fitted as
        if on the grid); a larger one is a gap or irregular sampling, and a fit keeps what
        follows. In [0, 0.5).
    kind, frame_id : int or None, str
        The only measurement kind and frame_id accepted (None / "": those of the first
        measurement buffered).
    lift : EciLift or None
        Optional observable map (e.g. `EciLift`) the DMD learns instead of z (None: z).
    inflate_correlated : bool
        Scale the model part D of the k-th forecast's covariance of a gap by k (R + k D,
        see the module docstring).
    correlation_power : float
        The exponent p of that scaling (R + k^p D).
    noise_share : float
        The share a of the sensor noise R that a forecast's covariance keeps
        (a R + k^p D); 1 is the paper's floor Var(e) >= R, lower values only for studies
        (`bench/consistency_tradeoff.py`), in (0, 1].
    whiten : bool
        Learn noisy channels divided by their noise sigma (see the module docstring).
    """

    buffer_s: float = 21600.0
    retrain_period_s: float = 600.0
    delays: int = 120
    rank: int | None = None
    max_horizon_s: float = 7200.0
    cadence_s: float = 0.0
    grace: float = 0.5
    jitter: float = 0.1
    kind: int | None = None
    frame_id: str = ""
    lift: EciLift | None = None
    inflate_correlated: bool = True
    correlation_power: float = 1.0
    noise_share: float = 1.0
    whiten: bool = True

    def __post_init__(self) -> None:
        """Reject a `noise_share` outside (0, 1] or a `jitter` outside [0, 0.5) (ValueError)."""
        if not 0.0 < self.noise_share <= 1.0:
            raise ValueError(f"noise_share must be in (0, 1], got {self.noise_share}")
        if not 0.0 <= self.jitter < 0.5:
            raise ValueError(f"jitter must be in [0, 0.5) of a cadence, got {self.jitter}")


class EciLift:
    """Range/az/el from a known station <-> the GCRF position it implies (km).

    `model` is the tracker's `RazelModel` (station and reference epoch); times are on its
    clock (s since `model.jd0_utc`).
    """

    def __init__(self, model: RazelModel) -> None:
        self.model = model

    def _unix(self, t: np.ndarray) -> np.ndarray:
        """Unix (UTC) epochs of ``t`` (s since ``model.jd0_utc``)."""
        return self.model.unix0 + np.asarray(t, dtype=float)

    def forward(self, z: np.ndarray, t: np.ndarray) -> np.ndarray:
        """(..., 3) range/az/el at epochs t (...) -> (..., 3) GCRF positions, km."""
        return razel_to_gcrs(z, self._unix(t), self.model.station)

    def to_measurement(self, r: np.ndarray, t: np.ndarray) -> np.ndarray:
        """(..., 3) GCRF positions at epochs t (...) -> (..., 3) range/az/el (km, rad, rad)."""
        return razel_gcrs(r, self._unix(t), self.model.station)

    def residual(self, z: np.ndarray, t: np.ndarray) -> Callable[..., np.ndarray]:
        """Return the error function, in range/az/el, of lifted predictions of samples ``z``.

        Parameters
        ----------
        z : ndarray, shape (N, 3)
            Measured range km, azimuth rad, elevation rad.
        t : ndarray, shape (N,)
            Their epochs, s on the model's clock.

        Returns
        -------
        callable
            ``err(pred, target)`` for `HankelDMD.forecast_covariance`: lifted predictions
            ``pred`` (k, 3, J), GCRF km, of the samples with indices ``target`` (k, J) ->
            their error (k, 3, J) in range/az/el; the azimuth difference is wrapped to
            [-pi, pi).
        """

        def err(pred: np.ndarray, target: np.ndarray) -> np.ndarray:
            e = self.to_measurement(pred.transpose(0, 2, 1), t[target]) - z[target]
            e[..., 1] = wrap_pi(e[..., 1])
            out: np.ndarray = e.transpose(0, 2, 1)
            return out

        return err


LIVE_SURROGATE = SurrogateConfig(retrain_period_s=math.inf, grace=2.0)
"""Timing defaults of the live surrogate node (and so of the offline replay): forecast an
epoch two cadences after it was missed, which absorbs message latency between topics; no
periodic refits (a gap always refits on the buffer up to the last real measurement, and a
refit of a 15 h buffer takes ~0.2 s, during which a node at 1000x real time falls 200 sim s
behind its measurements)."""


CADENCE_SAMPLES = 64
"""Intervals the cadence is inferred from when none is configured: recent enough to follow
the stream, few enough to keep `add` and `due` O(1)."""


class Surrogate:
    """Hankel-DMD forecaster of one measurement stream (see the module docstring)."""

    def __init__(self, config: SurrogateConfig) -> None:
        self.config = config
        self.status = "waiting for measurements"
        self.fits = 0
        self.invalid = 0  # forecasts withheld because they are not valid measurements
        self.rejected: Problem = OK  # why `add` rejected its last measurement, if it did
        self.reset()

    def reset(self) -> None:
        """Forget the buffer and the model (a backwards clock jump)."""
        self._buf: deque[Measurement] = deque()
        self._dt = math.nan  # cadence inferred from the buffer (config.cadence_s == 0)
        self._model: HankelDMD | None = None
        self._model_t = -math.inf  # epoch of the last sample the model was trained on
        self._model_fit_at = -math.inf
        self._forecast: np.ndarray | None = None
        self._cov: np.ndarray | None = None
        self._scale: np.ndarray | None = None
        self._emitted = 0  # forecasts emitted in the current gap

    @property
    def last(self) -> Measurement | None:
        """The newest buffered measurement (always a real one), None if the buffer is empty."""
        return self._buf[-1] if self._buf else None

    def cadence(self) -> float:
        """Return the measurement interval, s: configured, else inferred (NaN: not yet)."""
        return self.config.cadence_s if self.config.cadence_s > 0 else self._dt

    def _infer_cadence(self) -> None:
        """Infer the cadence, s, from the last `CADENCE_SAMPLES` intervals in the buffer.

        The slope of a least-squares line through the last stamps against their slot
        numbers on the grid of the median interval: jitter averages out, a gap of whole
        cadences does not count. Regular stamps give the median interval itself. NaN when
        a cadence is configured or fewer than two stamps are buffered.
        """
        n = min(len(self._buf), CADENCE_SAMPLES + 1)
        if self.config.cadence_s > 0 or n < 2:
            self._dt = math.nan
            return
        t = np.array([self._buf[-i].t for i in range(n, 0, -1)])
        d = np.diff(t)
        dt = float(np.median(d))
        if np.abs(d - dt).max() <= 1e-9 * dt:
            self._dt = dt
            return
        slot = np.concatenate(([0.0], np.cumsum(np.rint(d / dt))))
        self._dt = float(np.polyfit(slot, t - t[0], 1)[0])

    def problem(self, m: Measurement) -> Problem:
        """Return why `add` would refuse `m`: (cause, reason), or ("", "") if it would not.

        Refused are: a forecast; a wrong kind or frame (against the configuration, else the
        buffer's); NaN/inf; an impossible range/az/el or covariance; a stamp not after the
        last one buffered. Each would stop every fit, or empty the buffer, while it stayed
        in it.
        """
        if m.source != Source.SENSOR:
            return Cause.IGNORED_FORECAST_INPUT, f"source {m.source} at t={m.t}: not a sensor"
        last = self.last
        kind = self.config.kind if self.config.kind is not None else getattr(last, "kind", None)
        frame = self.config.frame_id or getattr(last, "frame_id", "")
        problem = measurement_problem(m, kind, frame)
        if problem != OK:
            return problem
        if last is not None and m.t <= last.t:
            return Cause.REJECTED_STALE, f"t={m.t} not after the last buffered t={last.t}"
        return OK

    # ----------------------------------------------------------------------------------
    def add(self, m: Measurement) -> list[Measurement]:
        """Buffer a real measurement; returns forecasts still owed for epochs before it.

        A measurement `problem` finds fault with is ignored; `rejected` holds the (cause,
        reason), `status` says why. A real backwards clock jump goes through `reset()`.
        """
        self.rejected = cause, reason = self.problem(m)
        if cause:
            self.status = f"ignored: {reason}"
            return []
        last = self.last
        # forecasts owed for the epochs before m's own slot (m may be late by the jitter)
        owed = self.due(m.t - max(self.config.jitter, 1e-6) * self.cadence(), _closing=True)
        if last is not None:
            self._fill_gap(last, m)
        self._buf.append(m)
        while self._buf and self._buf[0].t < m.t - self.config.buffer_s:
            self._buf.popleft()
        self._infer_cadence()
        self._emitted = 0
        self._forecast = None
        if m.t - self._model_fit_at >= self.config.retrain_period_s:
            self._fit()
        elif self._model is None:
            need = 2 * self.config.delays + 2
            n = len(self._buf)
            self.status = (f"{n} samples buffered, a fit needs {need}" if n < need
                           else f"{n} samples buffered; fits when a gap starts")
        return owed

    def due(self, now: float, _closing: bool = False) -> list[Measurement]:
        """Forecasts for missed epochs up to sim time `now` not yet emitted."""
        last = self.last
        dt = self.cadence()
        if last is None or not math.isfinite(dt) or dt <= 0:
            return []
        grace = 0.0 if _closing else self.config.grace * dt
        n_due = math.floor((now - grace - last.t) / dt + 1e-9)
        n_max = math.floor(self.config.max_horizon_s / dt + 1e-9)
        n_due = min(n_due, n_max)
        if n_due <= self._emitted:
            return []
        if not self._ensure_forecast(n_max):
            return []
        forecast, cov = self._forecast, self._cov
        assert forecast is not None and cov is not None  # both set by _ensure_forecast
        out = []
        for k in range(self._emitted + 1, n_due + 1):
            z = forecast[:, k - 1]
            if last.kind == Kind.RANGE_AZ_EL and not razel_possible(z):
                self.invalid += 1  # not a possible range/az/el: withheld, not clipped
                self.status = f"forecast at t={last.t + k * dt} is not a valid range/az/el"
                continue
            R = cov[k - 1]
            out.append(Measurement(
                t=last.t + k * dt, z=forecast[:, k - 1].copy(), R=0.5 * (R + R.T),
                kind=last.kind, source=Source.FORECAST, object_id=last.object_id,
                frame_id=last.frame_id, horizon=k * dt,
            ))
        self._emitted = n_due
        return out

    def next_due(self) -> float:
        """Return the epoch (s) of the first missed epoch not forecast yet (inf: none can be).

        `due_through` of any time before it returns nothing.
        """
        last, dt = self.last, self.cadence()
        if last is None or not math.isfinite(dt) or dt <= 0:
            return math.inf
        k = self._emitted + 1
        if k > math.floor(self.config.max_horizon_s / dt + 1e-9):
            return math.inf
        return last.t + k * dt

    def due_through(self, t: float) -> list[Measurement]:
        """Forecasts for the missed epochs up to `t` (s) not yet emitted, without the grace.

        For a caller that knows every real measurement up to `t` has been added (a graph in
        lockstep): nothing late can still come for them.
        """
        return self.due(t, _closing=True)

    def _fill_gap(self, last: Measurement, m: Measurement) -> None:
        """Fill the missed epochs between `last` and `m`, the real measurement ending a gap.

        They get this gap's forecasts (source FORECAST), so that the buffer stays at a fixed
        cadence and the next gap can still be fitted on the whole window. Nothing is filled
        if m is off the cadence grid, the gap outlasted the forecasts, or a forecast is not a
        possible measurement; the fit then keeps the regular tail after the gap.
        """
        dt = self.cadence()
        steps = (m.t - last.t) / dt if math.isfinite(dt) and dt > 0 else math.nan
        n_miss = round(steps) - 1 if math.isfinite(steps) else 0
        if n_miss < 1 or abs(steps - round(steps)) > self.config.jitter or self._forecast is None:
            return
        if n_miss > self._forecast.shape[1]:
            return
        z = self._forecast[:, :n_miss]
        if last.kind == Kind.RANGE_AZ_EL and not razel_possible(z).all():
            return
        cov = self._cov
        assert cov is not None  # set with self._forecast by _ensure_forecast
        for k in range(1, n_miss + 1):
            self._buf.append(Measurement(
                t=last.t + k * dt, z=z[:, k - 1].copy(), R=cov[k - 1], kind=last.kind,
                source=Source.FORECAST, object_id=last.object_id, frame_id=last.frame_id,
                horizon=k * dt))

    # ----------------------------------------------------------------------------------
    def _ensure_forecast(self, n_steps: int) -> bool:
        """Compute, unless done, the forecasts and covariances of the next `n_steps` epochs.

        The epochs follow the last real measurement at the cadence; False when no model
        could be fitted.
        """
        if self._forecast is not None:
            return True
        last = self.last
        assert last is not None  # due() asks only with a measurement buffered
        if self._model is None or self._model_t != last.t:
            self._fit()
        if self._model is None:
            return False
        self._forecast = self._model.forecast(n_steps)
        lift = self.config.lift
        if lift is None:
            self._cov = self._model.forecast_covariance(n_steps)
        else:
            # Errors in the measurement space: the lifted samples carry the angle noise
            # times the range (10-130 km across the line of sight), which is not the noise
            # of a range/az/el at the forecast epoch; so the in-sample predictions are
            # mapped back to range/az/el and compared with what the sensor measured.
            self._cov = self._model.forecast_covariance(
                n_steps, lift.residual(self._fit_z, self._fit_t))
            t = last.t + self.cadence() * np.arange(1, n_steps + 1)
            self._forecast = lift.to_measurement(self._forecast.T, t).T
        if self._scale is not None:
            w = self._scale
            self._forecast = self._forecast * w[:, None]
            self._cov = self._cov * np.outer(w, w)[None]
        # Var(e) = R + D (paper section 4): R the sensor noise, D >= 0 (PSD) the model part
        R = np.asarray(last.R, dtype=float)
        D = psd_part(self._cov - R)
        if self.config.inflate_correlated:
            k = np.arange(1, n_steps + 1, dtype=float)
            D = D * (k ** self.config.correlation_power)[:, None, None]
        self._cov = self.config.noise_share * R + D
        return True

    def _fit(self) -> None:
        """Fit on the buffer; on failure keep no model and say why in `status`."""
        cfg = self.config
        self._model = None
        last = self.last
        assert last is not None  # fitted only with a measurement buffered
        self._model_t = last.t
        self._model_fit_at = last.t
        need = 2 * cfg.delays + 2
        if len(self._buf) < need:
            self.status = f"cannot fit: {len(self._buf)} samples buffered, need {need}"
            return
        Z = np.array([m.z for m in self._buf], dtype=float).T
        t = np.array([m.t for m in self._buf])
        dt = self.cadence()
        off = np.flatnonzero(np.abs(np.diff(t) - dt) > cfg.jitter * dt)
        tail = ""
        if off.size:  # keep the regular tail only
            cut = off[-1] + 1
            Z = Z[:, cut:]
            tail = (f"the interval of {t[cut] - t[cut - 1]:.6g} s before t={t[cut]} is not "
                    f"at a fixed cadence ({dt:.6g} s +- {cfg.jitter:.0%}: a gap or irregular "
                    f"sampling)")
            if Z.shape[1] < need:
                self.status = f"cannot fit: {tail}; {Z.shape[1]} samples after it, need {need}"
                return
            tail = f"; only after {tail}"
        if not np.isfinite(Z).all() or np.ptp(Z, axis=1).max() == 0.0:
            self.status = "cannot fit: constant or non-finite data"
            return
        angles = (1,) if last.kind == Kind.RANGE_AZ_EL else ()
        if cfg.lift is not None:
            self._fit_t = t[-Z.shape[1]:]
            self._fit_z = Z.T
            Z = cfg.lift.forward(self._fit_z, self._fit_t).T
            angles = ()
        # Whiten by the known sensor noise (each channel / its sigma) so that the noise is
        # i.i.d. across channels, as the automatic rank threshold assumes; noise-free, lifted
        # or angle data are learned in their own units (angles must stay in rad to unwrap).
        sig = np.sqrt(np.clip(np.diag(np.asarray(last.R, dtype=float)), 0.0, None))
        self._scale = (sig if cfg.whiten and cfg.lift is None and not angles
                       and np.all(sig > 0) else None)
        if self._scale is not None:
            Z = Z / self._scale[:, None]
        try:
            self._model = HankelDMD(cfg.delays, cfg.rank, angle_channels=angles).fit(Z)
        except (ValueError, np.linalg.LinAlgError) as exc:
            self.status = f"cannot fit: {exc}"
            self._model = None
            return
        self.fits += 1
        filled = sum(b.source == Source.FORECAST for b in list(self._buf)[-Z.shape[1]:])
        self.status = (f"fitted on {Z.shape[1]} samples"
                       + (f" ({filled} of them forecasts filling a gap)" if filled else "")
                       + f", rank {self._model.rank_}" + tail)
