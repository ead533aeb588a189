"""What a filter publishes between passes, scored: the error and the covariance's truth.

`published` runs the filter's publication policy (`core.gaps.publisher.GapPublisher`, the
filter node's and `replay --offline`'s) over a run's real measurements with its clock on
the truth's epochs, so the estimates are those a live run would record. `score_gaps`
scores them at the truth epochs that fall between two passes:

* the position error at every gap epoch (median), and over the gaps longer than
  `LONG_GAP_S` (median);
* the position error right after each pass (at the first truth epoch after its last
  measurement);
* the covariance's truth at gap epochs: the position NEES (3 dof) against chi2(3), the share
  of epochs inside its 95 % bound and the median NEES (whose expectation is 2.37, the median
  of chi2(3)).

Units: km, s; states GCRF.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from ssa_fusion.core.base.metrics import nees
from ssa_fusion.core.base.types import Measurement, StateEstimate
from ssa_fusion.core.gaps.estimator import EstimatorConfig, make_tracker
from ssa_fusion.core.gaps.fit_residual import FitResidualForecaster
from ssa_fusion.core.gaps.publisher import GapFill, GapPublisher
from ssa_fusion.core.measure.pass_windows import passes
from ssa_fusion.core.od.batch_ls import BatchOptions

LONG_GAP_S = 12 * 3600.0
"""Gaps longer than this (s) are scored on their own too."""

NEES3_95 = float(chi2.ppf(0.95, 3))
"""The 95 % bound of chi2(3): a position NEES above it is outside."""


def published(c: EstimatorConfig, real: list[Measurement], t_truth: np.ndarray,
              fill: GapFill) -> dict[float, StateEstimate]:
    """Return what the filter of `c` publishes over `real` (last estimate per epoch).

    Predictions every truth cadence (``t_truth[1] - t_truth[0]``), filled by `fill`; the
    clock advances to every truth epoch in turn, a measurement going before the tick of its
    own epoch.
    """
    return publish_run(c, real, t_truth, fill).estimates


@dataclass
class PublishedRun:
    """What the filter published (last estimate per epoch), and what its gaps cost.

    ``cpu_s``: the process CPU time (s) of the gap forecaster's fits (and corrections);
    ``choices``: how many gaps each `step_aside.Choice` took (a corrected fit's; else
    empty).
    """

    estimates: dict[float, StateEstimate]
    cpu_s: float
    choices: dict[str, int]


def publish_run(c: EstimatorConfig, real: list[Measurement], t_truth: np.ndarray,
                fill: GapFill, options: BatchOptions | None = None) -> PublishedRun:
    """Return `published`'s estimates with the forecaster's cost and choices.

    ``options``: the gap fit's own options (e.g. the high-fidelity force model) instead of
    the live ones (`GapPublisher.of`).
    """
    period = float(t_truth[1] - t_truth[0])
    pub = GapPublisher.of(make_tracker(c), period, fill, c, options)
    out: dict[float, StateEstimate] = {}
    events = sorted([(m.t, 0, i) for i, m in enumerate(real)]
                    + [(float(t), 1, -1) for t in t_truth])
    for t, tick, i in events:
        got = pub.advance(t, limit=10**6) if tick else pub.measurement(real[i])
        for e in got.estimates:
            out[e.t] = e
    f = pub.forecaster
    choices = ({str(k): v for k, v in f.choices.items()}
               if isinstance(f, FitResidualForecaster) else {})
    return PublishedRun(out, float(getattr(f, "cpu_s", 0.0)), choices)


@dataclass
class GapScores:
    """One run's published estimates scored between passes (module docstring).

    Errors in km (NaN where there is nothing to score); ``nees_in_95`` a fraction.
    """

    gap_epochs: int
    err_median_km: float
    long_gap_epochs: int
    long_err_median_km: float
    after_pass_median_km: float
    nees_in_95: float
    nees_median: float


def _median(v: np.ndarray) -> float:
    return float(np.median(v)) if v.size else math.nan


def score_gaps(estimates: dict[float, StateEstimate], real: list[Measurement],
               t_truth: np.ndarray, x_truth: np.ndarray) -> GapScores:
    """Score `estimates` (by epoch) at the truth epochs between the passes of `real`."""
    ps = passes(real)
    t_est = np.array(sorted(estimates))
    gap_t, long_t, after = [], [], []
    for (_, end), (nxt, _) in itertools.pairwise(ps):
        t0, t1 = real[end].t, real[nxt].t
        inside = t_truth[(t_truth > t0) & (t_truth < t1)]
        inside = inside[np.isin(inside, t_est)]
        gap_t.append(inside)
        if t1 - t0 > LONG_GAP_S:
            long_t.append(inside)
        after.append(inside[:1])
    idx = {float(t): k for k, t in enumerate(t_truth)}

    def errors(ts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if not ts.size:
            return np.zeros(0), np.zeros(0)
        x = np.array([estimates[float(t)].x for t in ts])
        P = np.array([estimates[float(t)].P for t in ts])
        xt = x_truth[[idx[float(t)] for t in ts]]
        d = x[:, :3] - xt[:, :3]
        return np.linalg.norm(d, axis=1), nees(d, P[:, :3, :3])

    all_t = np.concatenate(gap_t) if gap_t else np.zeros(0)
    err, n3 = errors(all_t)
    long_err, _ = errors(np.concatenate(long_t) if long_t else np.zeros(0))
    after_err, _ = errors(np.concatenate(after) if after else np.zeros(0))
    return GapScores(int(all_t.size), _median(err), int(long_err.size), _median(long_err),
                     _median(after_err),
                     float(np.mean(n3 <= NEES3_95)) if n3.size else math.nan, _median(n3))
