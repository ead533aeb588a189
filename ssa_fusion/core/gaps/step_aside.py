"""Whether a learned correction earns its place: validated on the object's own last passes.

A gap forecaster that corrects a cheap fit by what it learnt (`fit_residual`) is only worth
publishing where the correction predicts better than the fit alone. `StepAside` keeps the
score: at the end of each pass, the forecasts made at the end of the pass before (the plain
fit's and the corrected one, both from before the pass) predict the pass just measured, and
each prediction's misfit is the sum over its measurements of the squared whitened residual
``(z - h(x))^T R^-1 (z - h(x))`` (`batch_ls.whitened_residuals`): no truth, only the
object's own measurements, out of sample. The correction is used for the next gap only when,
over the last `STEP_ASIDE_PASSES` validated passes, its misfit is the smaller; otherwise
(and while nothing was validated) it steps aside and the plain fit is published. Every
choice is counted by its `Choice`.
"""

from __future__ import annotations

import enum
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from ssa_fusion.core.base.types import Measurement
from ssa_fusion.core.measure.measurement import MeasurementModel
from ssa_fusion.core.od.batch_ls import whitened_residuals

__all__ = ["STEP_ASIDE_PASSES", "Choice", "StepAside"]

STEP_ASIDE_PASSES = 2
"""Validated passes the choice weighs (the last ones): one pass's misfit is noisy, and the
correction is a slow signal (what the cheap model misses, day after day)."""


class Choice(enum.StrEnum):
    """What a gap's forecast is, as `StepAside` chose it."""

    CORRECTED = "corrected"
    """The fit corrected by what was learnt: it predicted the last passes better."""
    PLAIN = "plain"
    """The plain fit: the correction predicted the last passes no better (it stepped aside)."""
    UNVALIDATED = "unvalidated"
    """The plain fit: no pass has validated the correction yet."""


@dataclass
class StepAside:
    """The score of a correction against the plain fit on the object's last passes.

    Attributes
    ----------
    passes : int
        Validations weighed (the last ones).
    misfits : deque of (float, float)
        (plain, corrected) misfit of each validated pass, the newest last.
    counts : dict of Choice to int
        How many gaps each choice took.
    last : Choice or None
        The latest choice.
    """

    passes: int = STEP_ASIDE_PASSES
    misfits: deque[tuple[float, float]] = field(default_factory=deque)
    counts: dict[Choice, int] = field(default_factory=lambda: dict.fromkeys(Choice, 0))
    last: Choice | None = None

    def validate(self, measurements: Sequence[Measurement], model: MeasurementModel,
                 plain: ArrayLike, corrected: ArrayLike) -> None:
        """Score the two predictions (N, 6) of a pass's ``measurements`` made before it.

        A prediction that is not finite, or a measurement the model cannot predict, scores
        nothing.
        """
        xp, xc = np.asarray(plain, dtype=float), np.asarray(corrected, dtype=float)
        if not measurements or not (np.isfinite(xp).all() and np.isfinite(xc).all()):
            return
        try:
            a = float(whitened_residuals(measurements, model, xp).sum())
            b = float(whitened_residuals(measurements, model, xc).sum())
        except ValueError:
            return
        self.misfits.append((a, b))
        while len(self.misfits) > self.passes:
            self.misfits.popleft()

    def choice(self) -> Choice:
        """Return the choice the validations make now (not counted)."""
        if not self.misfits:
            return Choice.UNVALIDATED
        plain = sum(a for a, _ in self.misfits)
        corrected = sum(b for _, b in self.misfits)
        return Choice.CORRECTED if corrected < plain else Choice.PLAIN

    def decide(self) -> Choice:
        """Return the choice for the next gap, counted."""
        self.last = self.choice()
        self.counts[self.last] += 1
        return self.last
