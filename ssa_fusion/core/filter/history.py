"""Out-of-sequence support: the log of the steps a filter fused, and rollback along it.

The idea is Stone Soup's ``OOSUpdaterWrapper`` (``stonesoup/updater/oos.py``): keep the
chain of recent steps, each with the state before it, so that a measurement for an epoch
the filter has already passed can be put in its place: roll back to the state before the
first step at or after its epoch, fuse it, fuse the later steps again. `FusedHistory` is
that log; which of the later steps are fused again is the caller's rule (`tracker`).

The log keeps the steps fused since `HISTORY_REAL` real measurements back (a forecast
step older than that is forgotten with the real ones around it). Rollback sets the filter
back through `ExtendedKalmanFilter.restore`.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass

import numpy as np

from ssa_fusion.core.base.types import Measurement, Source
from ssa_fusion.core.filter.ekf import ExtendedKalmanFilter

HISTORY_REAL = 8
"""Real measurements back to which the filter keeps its fused steps, so that a forecast that
arrives after the real measurements that followed its epoch (a gap's last forecasts, which the
surrogate releases when the measurement ending the gap reaches it) can still go in front of
them; 8 cadences are 0.24 s of wall time at 1000x real time."""


@dataclass
class Snapshot:
    """The filter's epoch and estimate at one moment.

    Attributes
    ----------
    t : float
        Epoch of the estimate, s.
    x : ndarray, shape (n,)
        State.
    P : ndarray, shape (n, n)
        Covariance.
    """

    t: float
    x: np.ndarray
    P: np.ndarray


@dataclass
class FusedStep:
    """A measurement the filter fused, the state before it and the last real epoch then.

    Attributes
    ----------
    m : Measurement
        The measurement fused.
    before : Snapshot
        The filter before the step (its prediction to ``m.t`` included).
    t_real : float
        Epoch of the last real measurement fused before the step, s.
    """

    m: Measurement
    before: Snapshot
    t_real: float


class FusedHistory:
    """The steps fused since `keep_real` real measurements back, oldest first.

    Parameters
    ----------
    keep_real : int
        Real measurements back to which steps are kept (the oldest kept step is a real one).
    """

    def __init__(self, keep_real: int = HISTORY_REAL) -> None:
        self.keep_real = keep_real
        self.steps: list[FusedStep] = []

    def __len__(self) -> int:
        """Return the number of steps kept."""
        return len(self.steps)

    def at(self, k: int) -> FusedStep | None:
        """Return the k-th step kept (0: the oldest), or None for k past the newest."""
        return self.steps[k] if k < len(self.steps) else None

    def position(self, t: float) -> int:
        """Return the index of the first step at or after epoch `t` (len(self) if none)."""
        return bisect.bisect_left([e.m.t for e in self.steps], t)

    def position_after(self, t: float) -> int:
        """Return the index of the first step after epoch `t` (len(self) if none)."""
        return bisect.bisect_right([e.m.t for e in self.steps], t)

    def record(self, step: FusedStep) -> None:
        """Log a fused step (the newest); a real one trims the history to `keep_real` reals.

        Parameters
        ----------
        step : FusedStep
            The step just fused, after every step kept.
        """
        self.steps.append(step)
        if step.m.source == Source.FORECAST:
            return
        reals = [i for i, f in enumerate(self.steps) if f.m.source != Source.FORECAST]
        if len(reals) > self.keep_real:
            del self.steps[:reals[-self.keep_real]]

    def rollback(self, k: int, ekf: ExtendedKalmanFilter) -> list[FusedStep]:
        """Set `ekf` back to its estimate before the k-th step and forget the steps from k on.

        Parameters
        ----------
        k : int
            Index of a kept step (``0 <= k < len(self)``).
        ekf : ExtendedKalmanFilter
            The filter that fused the steps; restored to ``steps[k].before``.

        Returns
        -------
        list of FusedStep
            The steps undone, oldest first: the first one's ``before.t`` and ``t_real`` are
            the caller's epoch and last real epoch now.
        """
        tail = self.steps[k:]
        ekf.restore(tail[0].before.x, tail[0].before.P)
        del self.steps[k:]
        return tail
