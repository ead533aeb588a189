"""What a filter publishes in a gap between passes: `GapForecaster`, the live policy.

The residual fit (`residual.ResidualSurrogate`) learns what the filter's motion model leaves
out from the estimates at the ends of past passes; `GapForecaster` decides when and with
what it is used on a live stream: which estimate ends a pass (an anchor), when to fit (once
per pass end, when the gap is reached), and the forecast it tabulates for the gap's grid
epochs. The filter node and the catalog's `gap_bank.GapBank` run it.

Frames and units: GCRF km, km/s; times s (sim time, e.g. Unix s).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.types import Measurement, MotionModel
from ssa_fusion.core.gaps.residual import (
    LIVE_RESIDUAL,
    ResidualConfig,
    ResidualFit,
    ResidualSurrogate,
)
from ssa_fusion.core.gaps.residual_frame import orbit_propagator

__all__ = ["PLACEHOLDER_TRAJECTORY", "TABULATE_FIRST_S", "GapForecaster"]

Array = NDArray[np.float64]

PLACEHOLDER_TRAJECTORY = {MotionModel.KEPLER: MotionModel.TWO_BODY, MotionModel.J2: MotionModel.J2}
"""The trajectory (a `residual_frame.orbit_propagator` model) of each filter motion model a gap
forecaster serves."""

TABULATE_FIRST_S = 3 * 3600.0
"""Sim s after a pass end a fit's forecast is tabulated at first (`GapForecaster.extend`):
most gaps of a low orbit on a network end within it."""


@dataclass
class GapForecaster:
    """The residual surrogate on a filter's live stream: what to publish in a gap.

    `on_estimate` takes every estimate that fused a real measurement (epoch order). Once a
    prediction epoch lies `pass_break_s` or more after the newest of them, that estimate is
    a pass end: it becomes an anchor (`ResidualSurrogate.add_anchor`), the surrogate fits at
    it, and the fit's forecast is tabulated on the grid of multiples of `period_s` up to
    ``max_horizon_s`` after it, as far as it is asked for (`extend`): the first
    `TABULATE_FIRST_S`, then twice as many grid epochs each time the asked epoch lies
    beyond (each time from the pass end, the same integration and design: the same numbers
    as the whole grid at once; a gap a pass ends early skips the rest). `forecast(t)`
    returns that forecast at a grid epoch t of the gap (state km, km/s GCRF; covariance),
    or None: no fit (too few anchors, refused), t before `pass_break_s` after the pass or
    beyond the horizon. A real measurement always wins: the filter's own state is not
    touched.

    With a `physics` surrogate (`residual.PHYSICS_RESIDUAL`: the placeholder from the pass
    end, constant accelerations under a prior in its covariance, from the first pass end
    on) it takes the same anchors, and a gap the learned residual has no fit for (too
    few pass ends or too short a span yet, or refused) gets the physics fit's forecast
    instead; ``physics_fit`` says which the current fit is.
    """

    surrogate: ResidualSurrogate
    period_s: float
    pass_break_s: float = 600.0
    last: tuple[float, Array, Array] | None = None
    anchored_t: float = -math.inf
    fitted_t: float = -math.inf
    table: dict[float, tuple[Array, Array]] = field(default_factory=dict)
    fit: ResidualFit | None = None
    grid: Array = field(default_factory=lambda: np.zeros(0))
    tabulated: int = 0
    physics: ResidualSurrogate | None = None
    physics_fit: bool = False

    @classmethod
    def for_model(cls, motion_model: MotionModel | str, period_s: float,
                  cfg: ResidualConfig = LIVE_RESIDUAL,
                  physics: ResidualConfig | None = None) -> GapForecaster:
        """Build the forecaster of a filter with `motion_model` ("kepler" or "j2").

        `physics`: the fit of the gaps the learned residual (`cfg`) has none for (None:
        none, those gaps get no forecast).
        """
        prop = orbit_propagator(PLACEHOLDER_TRAJECTORY[MotionModel(motion_model)])
        return cls(ResidualSurrogate(cfg, prop), float(period_s),
                   physics=None if physics is None else ResidualSurrogate(physics, prop))

    def on_estimate(self, t: float, x: ArrayLike, P: ArrayLike) -> None:
        """Take the filter's estimate (epoch t s) after it fused a real measurement.

        The previous one is a pass end (an anchor) when t is `pass_break_s` or more after it.
        A second estimate at the same epoch (another station's measurement fused after the
        first) replaces it.
        """
        if self.last is not None and t < self.last[0]:
            return
        if self.last is not None and t - self.last[0] >= self.pass_break_s:
            self._anchor()
        self.last = (float(t), np.asarray(x, float).copy(), np.asarray(P, float).copy())

    def on_measurement(self, m: Measurement) -> None:
        """Take a real measurement the filter fused: unused (the residual learns from estimates)."""

    def _anchor(self) -> bool:
        """Make the newest estimate an anchor, once; True when it became one now."""
        if self.last is None or self.last[0] <= self.anchored_t:
            return False
        t_end, x, P = self.last
        self.anchored_t = t_end
        try:
            self.surrogate.add_anchor(t_end, x, P)
            if self.physics is not None:
                self.physics.add_anchor(t_end, x, P)
        except ValueError:
            return False
        return True

    def forecast(self, t: float) -> tuple[Array, Array] | None:
        """Return the surrogate's state and covariance at gap epoch t (s), or None."""
        if self.last is None or t - self.last[0] < self.pass_break_s:
            return None
        t_end = self.last[0]
        self._anchor()
        if self.fitted_t != t_end:  # a pass ended: fit once, tabulate the forecast
            self.fitted_t = t_end
            self.table, self.fit, self.tabulated, self.physics_fit = {}, None, 0, False
            k0 = math.floor(t_end / self.period_s) + 1
            k1 = math.floor((t_end + self.surrogate.cfg.max_horizon_s) / self.period_s)
            self.grid = self.period_s * np.arange(k0, k1 + 1, dtype=float)
            self.fit = _fit(self.surrogate)
            if self.fit is None and self.physics is not None:
                self.fit = _fit(self.physics)
                self.physics_fit = self.fit is not None
            self.extend(t_end + TABULATE_FIRST_S)
        self.extend(float(t))
        return self.table.get(float(t))

    @property
    def pending(self) -> bool:
        """Return whether grid epochs of the fit are left to tabulate (`extend`)."""
        return self.fit is not None and self.tabulated < self.grid.size

    def extend(self, until: float) -> None:
        """Tabulate the fit's forecast at every grid epoch up to `until` (s), if not yet.

        At least twice the grid epochs tabulated so far (from the first, one prediction:
        the same numbers as the whole grid's); those whose state or covariance is not
        finite are left out. A prediction that fails ends the tabulation there.
        """
        need = int(np.searchsorted(self.grid, until, side="right"))
        if not self.pending or need <= self.tabulated:
            return
        assert self.fit is not None
        n = min(max(need, 2 * self.tabulated), self.grid.size)
        try:  # a propagation that fails leaves the rest of the gap to the EKF's coasting
            xs, Ps = self.fit.predict(self.grid[:n])
        except (ValueError, RuntimeError, ArithmeticError, np.linalg.LinAlgError):
            self.fit = None
            return
        for i in range(self.tabulated, n):
            if np.isfinite(xs[i]).all() and np.isfinite(Ps[i]).all():
                self.table[float(self.grid[i])] = (xs[i], Ps[i])
        self.tabulated = n


def _fit(surrogate: ResidualSurrogate) -> ResidualFit | None:
    """Return `surrogate`'s fit at its newest anchor; None: none, or it failed.

    A fit that fails leaves the gap to the EKF's coasting (or to the next fit tried).
    """
    try:
        return surrogate.fit()
    except (ValueError, RuntimeError, ArithmeticError, np.linalg.LinAlgError):
        return None
