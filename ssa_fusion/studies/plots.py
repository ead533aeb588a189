"""Plots of the offline reproduction (matplotlib; never imported by the core).

Figures are made with `matplotlib.figure.Figure`, not pyplot: no backend is chosen, no
global figure state kept (importing this module changes nothing in the process), and PNGs
are written by the Agg renderer whatever the importer's backend is.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from matplotlib.figure import Figure

if TYPE_CHECKING:
    from ssa_fusion.evaluation.arms import ArmName, ArmTrajectory
    from ssa_fusion.sim.simulate import Simulation

ARM_STYLE = {
    "placeholder": dict(color="tab:red", label="placeholder alone (MC, 200)"),
    "coast": dict(color="tab:gray", label="EKF coasting (no surrogate)", ls=":"),
    "j2_coast": dict(color="tab:purple", label="J2 EKF coasting", ls="-."),
    "batch_fit": dict(color="tab:brown", label="J2 batch fit (3 passes)"),
    "dmd_ekf": dict(color="tab:blue", label="DMD-EKF"),
    "hypothetical_ekf": dict(color="tab:green", label="hypothetical EKF", ls="--"),
}
STATE_NAMES = {6: ["x", "y", "z", "u", "v", "w"], 2: ["θ or x", "rate"]}


def subplots(nrows: int = 1, ncols: int = 1, *, figsize: tuple[float, float] | None = None,
             sharex: bool = False) -> tuple[Figure, Any]:
    """Return a new figure and its axes, as `matplotlib.pyplot.subplots` (without pyplot).

    The axes are one `Axes`, or an array of them for several rows or columns.
    """
    fig = Figure(figsize=figsize)
    return fig, fig.subplots(nrows, ncols, sharex=sharex)


def save(fig: Figure, path: Path, dpi: int = 110) -> None:
    """Lay out and write a figure as PNG (every plot of the project ends here)."""
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)


def _pointwise_error(x_hat: np.ndarray, x_true: np.ndarray, pos_max: float,
                     vel_max: float) -> np.ndarray:
    """Return the pointwise normalised error: |dr| / `pos_max` + |dv| / `vel_max`."""
    d = x_hat.shape[1] // 2
    e = x_hat - x_true
    err: np.ndarray = (np.linalg.norm(e[:, :d], axis=1) / pos_max
                       + np.linalg.norm(e[:, d:], axis=1) / vel_max)
    return err


def error_plot(name: str, sim: Simulation, arms: dict[ArmName, ArmTrajectory], path: Path,
               time_unit: str) -> Path:
    """Plot the pointwise normalised error (the summand of epsilon) of every arm against time.

    `time_unit`: "h" (sim seconds shown in hours) or the label of the sim's own unit.
    """
    d = sim.x.shape[1] // 2
    gap = sim.gap_index
    pos_max = np.max(np.linalg.norm(sim.x[gap, :d], axis=1))
    vel_max = np.max(np.linalg.norm(sim.x[gap, d:], axis=1))
    scale, unit = (3600.0, "h") if time_unit == "h" else (1.0, time_unit)
    fig, ax = subplots(figsize=(8, 4.2))
    for key, arm in arms.items():
        idx = np.searchsorted(sim.t, arm.t)
        e = _pointwise_error(arm.x, sim.x[idx], pos_max, vel_max)
        ax.semilogy((arm.t - sim.t[0]) / scale, np.maximum(e, 1e-16),
                    lw=1.2, **ARM_STYLE[str(key)])
    ax.axvspan((sim.t[gap[0]] - sim.t[0]) / scale, (sim.t[gap[-1]] - sim.t[0]) / scale,
               color="k", alpha=0.08, label="gap (sensor out)")
    ax.set_xlabel(f"time since first measurement [{unit}]")
    ax.set_ylabel("‖Δr‖/max‖r‖ + ‖Δv‖/max‖v‖")
    ax.set_title(f"{name}: estimation error of every arm over the gap")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    save(fig, path)
    return path


def sigma_plot(name: str, sim: Simulation, arm: ArmTrajectory, path: Path,
               time_unit: str) -> Path:
    """Plot the DMD-EKF's error per state with its ±3σ bounds, around and through the gap."""
    n = sim.x.shape[1]
    gap = sim.gap_index
    span = len(gap)
    arm_idx = np.searchsorted(sim.t, arm.t)
    lo = max(int(arm_idx[0]), int(gap[0]) - span)
    keep = arm_idx >= lo
    idx = arm_idx[keep]
    err = arm.x[keep] - sim.x[idx]
    sig = np.sqrt(np.einsum("kii->ki", arm.P[keep]))
    scale, unit = (3600.0, "h") if time_unit == "h" else (1.0, time_unit)
    t = (sim.t[idx] - sim.t[0]) / scale
    names = STATE_NAMES.get(n, [f"x{i}" for i in range(n)])
    rows = (n + 1) // 2
    fig, axes = subplots(rows, 2, figsize=(9, 2.0 * rows + 0.8), sharex=True)
    for i, ax in enumerate(np.atleast_1d(axes).ravel()[:n]):
        ax.plot(t, err[:, i], color="tab:blue", lw=0.9, label="error")
        ax.plot(t, 3 * sig[:, i], color="tab:orange", lw=0.9, label="±3σ")
        ax.plot(t, -3 * sig[:, i], color="tab:orange", lw=0.9)
        ax.axvspan((sim.t[gap[0]] - sim.t[0]) / scale, (sim.t[gap[-1]] - sim.t[0]) / scale,
                   color="k", alpha=0.08)
        ax.set_ylabel(names[i])
        ax.grid(True, alpha=0.3)
    np.atleast_1d(axes).ravel()[0].legend(fontsize=7)
    fig.suptitle(f"{name}: DMD-EKF error and ±3σ (gap shaded)")
    for ax in np.atleast_1d(axes).ravel()[-2:]:
        ax.set_xlabel(f"time [{unit}]")
    save(fig, path)
    return path


def vdp_sweep_plot(sweep: dict[str, list[float]], path: Path) -> Path:
    """Plot epsilon of each arm against the placeholder's mu_p (`experiments.vdp_sweep`)."""
    fig, ax = subplots(figsize=(6.5, 4))
    for key in ("placeholder", "dmd_ekf", "hypothetical_ekf"):
        ax.semilogy(sweep["mu_p"], sweep[key], marker="o", ms=3, **ARM_STYLE[key])
    ax.axvline(2.0, color="k", lw=0.8, ls=":", label="true μ = 2")
    ax.set_xlabel("placeholder μ_p")
    ax.set_ylabel("ε over the gap")
    ax.set_title("Van der Pol: error against the placeholder's μ_p")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    save(fig, path)
    return path


def consistency_plot(study: dict[str, Any], path: Path) -> Path:
    """Plot the forecast error variance (trace) against horizon.

    One-shot vs retrained, measured and as predicted by the surrogate.
    """
    fig, ax = subplots(figsize=(7, 4.2))
    h = np.asarray(study["horizon_s"]) / study.get("time_scale", 1.0)
    for key, color in (("one_shot", "tab:red"), ("retrained", "tab:blue")):
        d = study[key]
        ax.semilogy(h, d["empirical_var"], color=color, label=f"{key.replace('_', '-')}: "
                    "measured Var(e)")
        ax.semilogy(h, d["predicted_var"], color=color, ls="--",
                    label=f"{key.replace('_', '-')}: surrogate's covariance")
    ax.set_xlabel(f"time since training ended [{study.get('time_unit', 's')}]")
    ax.set_ylabel("trace of forecast error covariance")
    ax.set_title(f"Consistency of the surrogate ({study['scenario']})")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    save(fig, path)
    return path
