"""A gap forecast's covariance calibrated on the object's own last passes: right, not safe.

A fit's realistic covariance is what its settings (considered accelerations, process noise)
say the model leaves out; where the world has more than the settings assumed (a richer
truth than the one they were chosen on) or less, the covariance is too small or too large.
`CovarianceScale` measures it on the object's own data, without a truth: at the end of each
pass, the forecast published at the end of the pass before predicted the pass just
measured, and the factor k on that forecast's covariance for which its measurements' mean
normalised innovation squared equals one per channel,

    sum_i r_i^T (k S_i + I)^-1 r_i = sum_i dim(z_i)

(``r`` the whitened residual, ``S`` the whitened predicted covariance of each measurement,
`batch_ls.whitened_predictions`), is that pass's estimate (`scale_estimate`; bounded to
[`MIN_SCALE`, `MAX_SCALE`]; where the noise alone explains the misfit, `MIN_SCALE`), at
that pass's horizon h (from the forecast's epoch to the pass's mean epoch).

The factor is fitted to the last `SCALE_PASSES` estimates (1 before the first), by one of
three rules (`ScaleRule`). A model's error need not grow through a gap as its covariance
does: a fit that lacks the tesseral harmonics errs by kilometres after half a day and by
little after an orbit, and one radar's passes mostly score one-orbit horizons. ``MEDIAN``:
the median of the estimates, at every horizon. ``HORIZON`` (the default): at a horizon h,
the median of the estimates made at horizons of at least `REACH` h (those that saw that
far); beyond the longest horizon h_L that any saw, the median k_L of those at h_L with its
excess over one grown as a power of the horizon, ``1 + (k_L - 1) (h / h_L)^p``
(`EXCESS_POWER` p; at most `MAX_SCALE`; a factor below one stays as it is): a model error
the fit's covariance missed at h_L grows on through the gap, and none is made up where the
passes showed none. ``POWER_LAW``: a power of the horizon fitted to the estimates,
``log k = a + b log h`` (least squares; b within [`MIN_POWER`, `MAX_POWER`]) when their
horizons span at least a factor `HORIZON_SPREAD` (else the median). On tuning seed 1 of
iss_radar_columbus with the high-fidelity truth (`bench/bench_sky.py`'s case) the live gap
fit's median position NEES at gap epochs was 21.1 with the power law, 11.5 with the median
(440 uncalibrated): one radar sees a long gap's horizon once a day, too seldom for a law.
`CovarianceScale.factor` gives the factor at any horizon.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import Enum

import numpy as np
from numpy.typing import ArrayLike

from ssa_fusion.core.base.types import Measurement
from ssa_fusion.core.measure.measurement import MeasurementModel
from ssa_fusion.core.od.batch_ls import whitened_predictions

__all__ = ["MAX_SCALE", "MIN_SCALE", "SCALE_PASSES", "CovarianceScale", "ScaleRule",
           "scale_estimate"]

SCALE_PASSES = 6
"""Estimates the factor is fitted to (the last passes'): a day of one radar's passes, short
gaps (an orbit) and long ones (half a day) among them."""
REACH = 1.0
"""``HORIZON``: an estimate counts at horizons up to 1 / REACH times its own (1: up to its
own). On tuning seeds 1-3 of iss_radar_columbus (start 0 h, high-fidelity truth) the live
gap fit's median position NEES at gap epochs was 5.78 with 1, 6.29 with 0.5, 13.3 with
``MEDIAN``; with `SCALE_PASSES` 12 and 3 (reach 1) 10.6 and 5.33."""
EXCESS_POWER = 2.0
"""``HORIZON``: the power p of the horizon with which the excess of the factor over one grows
beyond the longest horizon an estimate saw (module docstring). A network's passes score
horizons of an hour or two, and its gap fit's NEES grew through its longer gaps. Of {0, 1,
2, 3}, on the tuning runs with the high-fidelity truth (`bench/bench_sky.py --gaps-only
--tuning --scale-excess-power P`, seeds 1-3 x start 0/8/16 h; median over runs of the
published `batch_init`'s median position NEES at gap epochs / its coverage of chi2(3)'s 95 %
bound): iss_radar_columbus 2.83 / 2.83 / 2.83 / 1.59 and 65.6 % at all four, iss_network
3.52 / 2.27 / 1.97 / 1.90 and 65.7 / 66.4 / 66.9 / 66.9 %. 2: the largest whose medians
stay in [1.6, 3.7] on both. With the SGP4 truth (one radar 0.0307, network 0.0196 at 0 and
2) it changes nothing: its passes show no excess."""
HORIZON_SPREAD = 2.0
"""The least ratio of the longest horizon to the shortest for the power law."""
MIN_POWER, MAX_POWER = -2.0, 4.0
"""Bounds of the power b of the horizon."""
MIN_SCALE = 1.0
"""The least factor: the calibration only ever widens the fit's covariance. With 0.05 and
the considered accelerations at 5e-9 km/s^2 (a covariance shrunk where a pass's misfit is
the noise's) the live gap fit's median position NEES at gap epochs was 7.46 (one radar) and
16.7 (network) on evaluation runs with the SGP4 truth (`bench/bench_sky.py --gaps-only
--truth sgp4 --eval-seeds 4 --offsets 0`), against 1.37 and 1.24 uncalibrated: a pass that
the fit predicts to the noise says nothing of how small its covariance may be. At 3e-7
(`batch_gap.GAP_FIT_ACCEL_SIGMA`) 0.01 would mend the SGP4 world's caution (tuning runs,
`--tuning --truth sgp4 --scale-min 0.01`: median NEES 0.781 / 1.63, coverage 83.4 / 88.7 %,
against 0.0307 / 0.0196 and 100 / 99.7 % at 1) but not the world the default is set for
(high-fidelity tuning runs, `EXCESS_POWER` 0: 3.76 / 3.64 and 59.0 / 60.6 % against 2.83 /
3.52 and 65.6 / 65.7 %). The most likely k (each channel weighed by its ``lam``, so that
the ones the prediction does not reach count for nothing) instead of `scale_estimate`'s
mean did worse there: 3.03 / 4.71 and 63.7 / 57.0 % at 1, 4.89 / 7.58 and 55.4 / 50.6 % at
0.01: the channels a pass's prediction barely reaches still carry the richer world's misfit
that the gap shows."""
MAX_SCALE = 1e6
"""The largest factor (sigma a thousand times the fit's)."""


def scale_estimate(lam: ArrayLike, q2: ArrayLike) -> float:
    """Return k with ``sum(q2 / (k lam + 1)) = len(q2)``, bounded (module docstring).

    ``lam``, ``q2``: `batch_ls.whitened_predictions`' eigenvalues and squared components.
    NaN when there is nothing to estimate from.
    """
    lam_, q2_ = np.asarray(lam, dtype=float), np.asarray(q2, dtype=float)
    if not lam_.size or not np.isfinite(q2_).all() or not (lam_ > 0).any():
        return math.nan
    n = float(q2_.size)

    def excess(k: float) -> float:
        return float(np.sum(q2_ / (k * lam_ + 1.0))) - n

    if excess(MIN_SCALE) <= 0.0:
        return MIN_SCALE
    if excess(MAX_SCALE) >= 0.0:
        return MAX_SCALE
    lo, hi = math.log(MIN_SCALE), math.log(MAX_SCALE)
    for _ in range(60):  # bisection in log k: excess decreases with k
        mid = 0.5 * (lo + hi)
        if excess(math.exp(mid)) > 0.0:
            lo = mid
        else:
            hi = mid
    return math.exp(0.5 * (lo + hi))


class ScaleRule(Enum):
    """How the factor at a horizon follows from the last passes' estimates (module docstring)."""

    MEDIAN = "median"
    HORIZON = "horizon"
    POWER_LAW = "power_law"


SCALE_RULE = ScaleRule.HORIZON
"""The rule of a new `CovarianceScale` (read when it is made)."""


@dataclass
class CovarianceScale:
    """The factor on a gap forecast's covariance, from the object's last passes.

    Attributes
    ----------
    passes : int
        Estimates the factor is fitted to.
    estimates : deque of (float, float)
        The last passes' (horizon s, estimate), the newest last.
    rule : ScaleRule
        How the factor at a horizon follows from the estimates (module docstring).
    """

    passes: int = field(default_factory=lambda: SCALE_PASSES)
    estimates: deque[tuple[float, float]] = field(default_factory=deque)
    rule: ScaleRule = field(default_factory=lambda: SCALE_RULE)

    def factor(self, horizon_s: ArrayLike) -> np.ndarray:
        """Return the factor (n,) at horizons ``horizon_s`` (n,) (s after the forecast's epoch)."""
        h = np.maximum(np.atleast_1d(np.asarray(horizon_s, dtype=float)), 60.0)
        if not self.estimates:
            return np.ones_like(h)
        hs = np.array([a for a, _ in self.estimates])
        ks = np.log([b for _, b in self.estimates])
        if self.rule is ScaleRule.HORIZON:
            matched: np.ndarray = np.exp(_horizon_median(hs, ks, h))
            return matched
        if (self.rule is ScaleRule.MEDIAN or len(hs) < 3
                or hs.max() < HORIZON_SPREAD * hs.min()):
            return np.full_like(h, math.exp(float(np.median(ks))))
        lh = np.log(hs)
        b = float(np.clip(np.polyfit(lh, ks, 1)[0], MIN_POWER, MAX_POWER))
        a = float(np.mean(ks - b * lh))
        out: np.ndarray = np.clip(np.exp(a + b * np.log(h)), MIN_SCALE, MAX_SCALE)
        return out

    def update(self, measurements: Sequence[Measurement], model: MeasurementModel,
               x: ArrayLike, P: ArrayLike, horizon_s: float) -> None:
        """Estimate from a pass's ``measurements`` and the forecast (``x``, ``P``) made before.

        ``horizon_s``: from the forecast's epoch to the pass's mean epoch. A forecast that
        is not finite, or a measurement the model cannot predict, estimates nothing.
        """
        xs, Ps = np.asarray(x, dtype=float), np.asarray(P, dtype=float)
        if not measurements or not (np.isfinite(xs).all() and np.isfinite(Ps).all()):
            return
        try:
            k = scale_estimate(*whitened_predictions(measurements, model, xs, Ps))
        except (ValueError, np.linalg.LinAlgError):
            return
        if math.isfinite(k):
            self.estimates.append((float(horizon_s), k))
            while len(self.estimates) > self.passes:
                self.estimates.popleft()


def _horizon_median(hs: np.ndarray, ks: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Return the log factor at each horizon of ``h`` (n,) by ``ScaleRule.HORIZON``.

    ``hs``, ``ks`` (m,): the estimates' horizons (s) and log factors.
    """
    seen = hs[None, :] >= REACH * h[:, None]
    k_l = math.exp(float(np.median(ks[hs == hs.max()])))
    beyond = np.maximum(REACH * h / hs.max(), 1.0) ** EXCESS_POWER
    out = (np.log1p(np.minimum((k_l - 1.0) * beyond, MAX_SCALE)) if k_l > 1.0
           else np.full(h.shape, math.log(k_l)))
    for pattern in np.unique(seen[seen.any(axis=1)], axis=0):  # few: the sets nest
        rows = (seen == pattern).all(axis=1)
        out[rows] = float(np.median(ks[pattern]))
    return out
