"""Evaluate a bag the graph recorded: the paper's three arms over the gap.

* placeholder: the Keplerian model alone, Monte Carlo over 200 particles drawn from the
  last estimate before the gap and its covariance (paper section 3);
* dmd_ekf: the estimates the filter published live during the gap (fusing forecasts); at a
  gap epoch without one (no forecast, or one refused), the filter's prediction from the last
  estimate before it, as `experiments.run_dmd_ekf` scores it;
* hypothetical_ekf: the same EKF run offline on the real measurements *and* the withheld
  ones (what the filter would have done had the sensor not been out).

Errors use the paper's normalized ε over every gap epoch (`/ssa/withheld` stamps), for every
arm, against `/ssa/truth`.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ssa_fusion.core import metrics, types
from ssa_fusion.paper import scenarios
from ssa_fusion.paper.montecarlo import placeholder_ensemble
from ssa_fusion.paper.pipeline import make_tracker
from ssa_fusion.ros import bagio
from ssa_fusion.ros.messages import estimate_from_msg, measurement_from_msg
from ssa_fusion.ros.topics import (
    TOPIC_ESTIMATE,
    TOPIC_FORECAST,
    TOPIC_MEASUREMENT,
    TOPIC_TRUTH,
    TOPIC_WITHHELD,
)


@dataclass
class BagData:
    """Decoded topics of a bag, in core units (km, km/s, rad, s)."""

    truth: list[types.StateEstimate] = field(default_factory=list)
    estimates: list[types.StateEstimate] = field(default_factory=list)
    measurements: list[types.Measurement] = field(default_factory=list)
    withheld: list[types.Measurement] = field(default_factory=list)
    forecasts: list[types.Measurement] = field(default_factory=list)
    counts: dict[str, int] = field(default_factory=dict)


def load(path: Path | str) -> BagData:
    """Read the /ssa topics of a bag into core types (other topics are counted only)."""
    data = BagData()
    lists = {
        TOPIC_TRUTH: (data.truth, estimate_from_msg),
        TOPIC_ESTIMATE: (data.estimates, estimate_from_msg),
        TOPIC_MEASUREMENT: (data.measurements, measurement_from_msg),
        TOPIC_WITHHELD: (data.withheld, measurement_from_msg),
        TOPIC_FORECAST: (data.forecasts, measurement_from_msg),
    }
    for m in bagio.read_bag(path):
        data.counts[m.topic] = data.counts.get(m.topic, 0) + 1
        if m.topic in lists:
            target, convert = lists[m.topic]
            target.append(convert(m.msg))
    return data


def scenario_for(data: BagData, name: str = "") -> scenarios.Scenario:
    """The scenario whose estimator settings evaluate this bag (by name, else by kind)."""
    kind = data.measurements[0].kind if data.measurements else types.Kind.POSITION
    return scenarios.settings_for(name, kind)


def run_tracker(s: scenarios.Scenario, stream: list[types.Measurement]) -> dict:
    """Run the scenario's EKF over `stream` in epoch order; last estimate per epoch."""
    tracker = make_tracker(s)
    out: dict[float, types.StateEstimate] = {}
    for m in sorted(stream, key=lambda m: (m.t, m.source)):
        o = tracker.process(m)
        for e in [o.estimate, *o.fused_again]:
            if e is not None:
                out[e.t] = e
    return out


def dmd_ekf_arm(s: scenarios.Scenario, live: dict[float, types.StateEstimate],
                t_gap: np.ndarray) -> list[types.StateEstimate]:
    """The live estimate at each gap epoch, else the filter's prediction there
    (`Tracker.predict_from`) from the last live estimate before it (one exists before the gap)."""
    tracker = make_tracker(s)
    times = sorted(live)
    out = []
    for t in t_gap:
        e = live.get(t)
        if e is None:
            e = tracker.predict_from(live[times[bisect.bisect_left(times, t) - 1]], float(t))
        out.append(e)
    return out


@dataclass
class Evaluation:
    t: np.ndarray  # gap epochs, s
    truth: np.ndarray  # (k, 6)
    arms: dict[str, np.ndarray]  # arm -> (k, 6) estimates at the gap epochs
    covs: dict[str, np.ndarray]  # arm -> (k, 6, 6)
    epsilon: dict[str, float]
    nees_mean: dict[str, float]
    coverage: float  # fraction of gap epochs with a live DMD-EKF estimate
    propagated: int  # gap epochs where dmd_ekf is the prediction from an earlier estimate


def evaluate(data: BagData, scenario: str = "", seed: int = 0) -> Evaluation:
    """The three arms over the gap (see the module docstring)."""
    if not data.withheld:
        raise ValueError("the bag has no /ssa/withheld messages: no gap to evaluate")
    if not data.truth:
        raise ValueError("the bag has no /ssa/truth messages: nothing to compare against")
    s = scenario_for(data, scenario)
    t_gap = np.array(sorted({m.t for m in data.withheld}))
    truth = {e.t: e.x for e in data.truth}
    missing = [t for t in t_gap if t not in truth]
    if missing:
        raise ValueError(f"/ssa/truth lacks {len(missing)} gap epochs (first t={missing[0]})")
    x_true = np.array([truth[t] for t in t_gap])

    live = {}
    for e in data.estimates:
        if e.update_source != types.UpdateSource.NONE:
            live[e.t] = e
    before = [e for t, e in live.items() if t < t_gap[0] and e.update_source == 1]
    if not before:
        raise ValueError("no estimate before the gap: the filter never initialised")
    start = max(before, key=lambda e: e.t)

    dt = np.concatenate([[0.0], t_gap - start.t])  # the ensemble starts at the estimate
    mean, cov = placeholder_ensemble("kepler", start.x, start.P, dt, seed)
    mean, cov = mean[1:], cov[1:]
    hyp = run_tracker(s, data.measurements + data.withheld)
    arms = {"placeholder": mean, "hypothetical_ekf": np.array([hyp[t].x for t in t_gap])}
    covs = {"placeholder": cov, "hypothetical_ekf": np.array([hyp[t].P for t in t_gap])}
    have = [t in live for t in t_gap]
    dmd = dmd_ekf_arm(s, live, t_gap)
    arms["dmd_ekf"] = np.array([e.x for e in dmd])
    covs["dmd_ekf"] = np.array([e.P for e in dmd])
    eps, nees = {}, {}
    for arm, x in arms.items():
        eps[arm] = metrics.epsilon(x, x_true)
        nees[arm] = float(np.mean(metrics.nees(x - x_true, covs[arm])))
    return Evaluation(t_gap, x_true, arms, covs, eps, nees, float(np.mean(have)),
                      len(have) - sum(have))


def table(ev: Evaluation) -> str:
    """Markdown table of the arms."""
    rows = ["| arm | ε over the gap | mean NEES |", "|---|---|---|"]
    for arm in ("placeholder", "dmd_ekf", "hypothetical_ekf"):
        v = ev.nees_mean[arm]
        rows.append(f"| {arm} | {ev.epsilon[arm]:.3e} | {v:.2f} |" if abs(v) < 1e4
                    else f"| {arm} | {ev.epsilon[arm]:.3e} | {v:.2e} |")
    rows.append(f"\ngap: {len(ev.t)} epochs; live DMD-EKF estimates at "
                f"{100 * ev.coverage:.0f} % of them"
                + (f"; dmd_ekf at the other {ev.propagated} scored from the last estimate "
                   "before, propagated by the placeholder" if ev.propagated else ""))
    return "\n".join(rows)
