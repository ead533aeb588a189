"""Passes and the gaps between them: how a filter did after each pass and through the gaps.

A station sees a low orbit in passes of minutes separated by hours; `passes` cuts a
measurement stream into them, `pass_report` scores a filter's estimates against the truth
after each pass and at every truth epoch (the estimate there, or the prediction from the last
one: what the live filter publishes through a gap), and `outage_epochs` picks the truth epochs
a scheduled outage is scored over. The same code scores a simulated run and a recorded bag.

Units: km, km/s, rad, s; times are Unix seconds (UTC); states GCRF.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ssa_fusion.core.base.metrics import chi2_bounds, nees
from ssa_fusion.core.base.types import Measurement, StateEstimate
from ssa_fusion.core.gaps.estimator import EstimatorConfig
from ssa_fusion.core.measure.pass_windows import PASS_BREAK_S, passes
from ssa_fusion.evaluation import arms

__all__ = ["PASS_BREAK_S", "PassReport", "estimates_at", "outage_epochs", "pass_report", "passes"]

@dataclass
class PassReport:
    """How the filter did through the passes and gaps of a run.

    passes : per pass, (end epoch s, station ids, measurements fused, position error km and
    position sigma km (sqrt of the trace of the position covariance) at the first truth
    epoch after the pass); t_start : the first truth epoch, s; t, pos_err_km, nees : the
    filter's estimate or prediction at each truth epoch after its first estimate;
    nees_band : the per-epoch 95 % chi-square band (6 dof); gaps_h : the gaps between passes, h.
    """

    passes: list[tuple[float, str, int, float, float]]
    t_start: float
    t: np.ndarray
    pos_err_km: np.ndarray
    nees: np.ndarray
    nees_band: tuple[float, float]
    gaps_h: np.ndarray

    @property
    def nees_in_band(self) -> float:
        """Fraction of truth epochs whose NEES lies in the 95 % band."""
        lo, hi = self.nees_band
        return float(np.mean((self.nees >= lo) & (self.nees <= hi)))

    def table(self) -> str:
        """Markdown: the per-pass errors, then the run's NEES and gaps."""
        rows = ["| pass end (h after start) | stations | measurements | position error after "
                "the pass [km] | its σ [km] |", "|---|---|---|---|---|"]
        for t_end, who, n, err, sig in self.passes:
            rows.append(f"| {(t_end - self.t_start) / 3600:.2f} | {who} | {n} | {err:.3f} "
                        f"| {sig:.3f} |")
        lo, hi = self.nees_band
        e = self.nees
        after = [p[3] for p in self.passes]
        if after:
            rows.append(f"\nafter each pass: median error {np.median(after):.3f} km, max "
                        f"{max(after):.3f} km over {len(after)} passes")
        rows.append(f"through the run ({len(e)} truth epochs): position error mean "
                    f"{np.mean(self.pos_err_km):.3f} km, max {np.max(self.pos_err_km):.3f} km; "
                    f"NEES mean {np.mean(e):.2f}, median {np.median(e):.2f}, per-epoch 95 % band "
                    f"[{lo:.2f}, {hi:.2f}] holds {100 * self.nees_in_band:.0f} % of epochs")
        if len(self.gaps_h):
            rows.append(f"gaps between passes: {len(self.gaps_h)}, {self.gaps_h.min():.2f} to "
                        f"{self.gaps_h.max():.2f} h")
        return "\n".join(rows)


def pass_report(c: EstimatorConfig, estimates: dict[float, StateEstimate],
                real: list[Measurement], t_truth: np.ndarray,
                x_truth: np.ndarray) -> PassReport:
    """Score a filter's estimates against the truth after each pass and at every truth epoch.

    `estimates`: by epoch, those that fused a measurement; the truth (`t_truth`, `x_truth`)
    is on a regular cadence. Scored after each pass of `real`, and at every truth epoch (the
    estimate there, or the prediction from the last one).
    """
    if not estimates:
        raise ValueError("the filter never published an estimate")
    traj = estimates_at(c, estimates, t_truth)
    x_true = x_truth[t_truth > min(estimates)]
    err = np.linalg.norm(traj.x[:, :3] - x_true[:, :3], axis=1)
    e = nees(traj.x - x_true, traj.P)
    fused = [m for m in real if m.t in estimates]
    rows = []
    for first, last in passes(fused):
        t_end = fused[last].t
        k = int(np.searchsorted(traj.t, t_end, side="right"))
        if k >= len(traj.t):
            continue
        who = ",".join(sorted({m.frame_id for m in fused[first:last + 1]}))
        rows.append((t_end, who, last - first + 1, float(err[k]),
                     float(np.sqrt(np.trace(traj.P[k, :3, :3])))))
    real_t = np.array([m.t for m in real])
    gaps = np.diff(real_t) if len(real_t) > 1 else np.zeros(0)
    return PassReport(rows, float(t_truth[0]), traj.t, err, e, chi2_bounds(6),
                      gaps[gaps > PASS_BREAK_S] / 3600.0)


def estimates_at(c: EstimatorConfig, estimates: dict[float, StateEstimate],
                 t: np.ndarray) -> arms.ArmTrajectory:
    """Return the filter's estimate, or its prediction from the last one, at epochs `t`.

    At every epoch of `t` after its first estimate (what the live filter publishes through
    the gaps).
    """
    first = min(estimates)
    return arms.at_epochs(c, estimates, t[t > first])


def outage_epochs(t: np.ndarray, withheld: list[Measurement]) -> np.ndarray:
    """Return the truth epochs of `t` the scheduled outage is scored over.

    From its first withheld measurement to its last (the same rule for a bag,
    `apps.evaluate`, which knows only what was withheld, not the schedule).
    """
    w = [m.t for m in withheld]
    return t[(t >= min(w)) & (t <= max(w))] if w else t[:0]
