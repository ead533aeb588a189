"""The measurement surrogate: a sliding buffer of real measurements, a Hankel-DMD model
retrained on it, and forecasts for the epochs the sensor missed.

`Surrogate.add(m)` takes real measurements; `Surrogate.due(now)` returns the forecasts that
have become due by sim time `now` (each missed epoch once). Which epochs get a forecast,
and its value, depend only on the measurements, never on when `due` is called: a gap is
the run of cadence epochs after the last real measurement, forecasts come from a model
trained on the buffer up to that measurement, and a real measurement that ends a gap first
releases the forecasts still owed for the epochs before it. This is what makes live runs
and offline replays give the same forecasts.

Each forecast carries the covariance R + Var(e(h)) of paper section 4: the sensor noise
plus the surrogate's forecast error covariance at horizon h, which grows with h.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from .hankel_dmd import HankelDMD
from .measurement import RANGE_AZ_EL
from .types import FORECAST, Measurement


@dataclass
class SurrogateConfig:
    """buffer_s : length of the sliding training buffer, s;
    retrain_period_s : refit at least this often (sim s) while measurements arrive; a gap
    always starts from a model fitted up to the last real measurement;
    delays, rank : Hankel-DMD settings (rank None: automatic);
    max_horizon_s : no forecast beyond this many s after the last real measurement;
    cadence_s : expected measurement interval (0: the median interval of the buffer);
    grace : fraction of a cadence after an epoch before it counts as missed."""

    buffer_s: float = 21600.0
    retrain_period_s: float = 600.0
    delays: int = 120
    rank: int | None = None
    max_horizon_s: float = 7200.0
    cadence_s: float = 0.0
    grace: float = 0.5


class Surrogate:
    """Hankel-DMD forecaster of one measurement stream (see the module docstring)."""

    def __init__(self, config: SurrogateConfig) -> None:
        self.config = config
        self.status = "waiting for measurements"
        self.fits = 0
        self.reset()

    def reset(self) -> None:
        """Forget the buffer and the model (a backwards clock jump)."""
        self._buf: deque[Measurement] = deque()
        self._model: HankelDMD | None = None
        self._model_t = -math.inf  # epoch of the last sample the model was trained on
        self._model_fit_at = -math.inf
        self._forecast: np.ndarray | None = None
        self._cov: np.ndarray | None = None
        self._emitted = 0  # forecasts emitted in the current gap

    @property
    def last(self) -> Measurement | None:
        return self._buf[-1] if self._buf else None

    def cadence(self) -> float:
        if self.config.cadence_s > 0:
            return self.config.cadence_s
        if len(self._buf) < 2:
            return math.nan
        t = np.array([m.t for m in self._buf])
        return float(np.median(np.diff(t)))

    # ----------------------------------------------------------------------------------
    def add(self, m: Measurement) -> list[Measurement]:
        """Buffer a real measurement; returns forecasts still owed for epochs before it."""
        owed = self.due(m.t - 1e-9 * max(1.0, abs(m.t)), _closing=True)
        last = self.last
        if last is not None and m.kind != last.kind:
            self.reset()
        self._buf.append(m)
        while self._buf and self._buf[0].t < m.t - self.config.buffer_s:
            self._buf.popleft()
        self._emitted = 0
        self._forecast = None
        if m.t - self._model_fit_at >= self.config.retrain_period_s:
            self._fit()
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
        out = []
        for k in range(self._emitted + 1, n_due + 1):
            R = last.R + self._cov[k - 1]
            out.append(Measurement(
                t=last.t + k * dt, z=self._forecast[:, k - 1].copy(), R=0.5 * (R + R.T),
                kind=last.kind, source=FORECAST, object_id=last.object_id,
                frame_id=last.frame_id, horizon=k * dt,
            ))
        self._emitted = n_due
        return out

    # ----------------------------------------------------------------------------------
    def _ensure_forecast(self, n_steps: int) -> bool:
        if self._forecast is not None:
            return True
        if self._model is None or self._model_t != self.last.t:
            self._fit()
        if self._model is None:
            return False
        self._forecast = self._model.forecast(n_steps)
        self._cov = self._model.forecast_covariance(n_steps)
        return True

    def _fit(self) -> None:
        """Fit on the buffer; on failure keep no model and say why in `status`."""
        cfg = self.config
        self._model = None
        last = self.last
        self._model_t = last.t
        self._model_fit_at = last.t
        need = 2 * cfg.delays + 2
        if len(self._buf) < need:
            self.status = f"cannot fit: {len(self._buf)} samples buffered, need {need}"
            return
        Z = np.array([m.z for m in self._buf], dtype=float).T
        t = np.array([m.t for m in self._buf])
        steps = np.diff(t)
        dt = self.cadence()
        if np.abs(steps - dt).max() > 1e-3 * dt:
            self.status = "cannot fit: samples not at a fixed cadence (a gap inside the buffer)"
            # keep the regular tail only
            cut = np.flatnonzero(np.abs(steps - dt) > 1e-3 * dt)[-1] + 1
            Z = Z[:, cut:]
            if Z.shape[1] < need:
                return
        if not np.isfinite(Z).all() or np.ptp(Z, axis=1).max() == 0.0:
            self.status = "cannot fit: constant or non-finite data"
            return
        angles = (1,) if last.kind == RANGE_AZ_EL else ()
        try:
            self._model = HankelDMD(cfg.delays, cfg.rank, angle_channels=angles).fit(Z)
        except (ValueError, np.linalg.LinAlgError) as exc:
            self.status = f"cannot fit: {exc}"
            self._model = None
            return
        self.fits += 1
        self.status = f"fitted on {Z.shape[1]} samples, rank {self._model.rank_}"
