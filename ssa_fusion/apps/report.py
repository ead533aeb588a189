"""`ssa-fusion report BAG`: the metrics table and plots of a bag the graph wrote.

Plots (PNG, in --out): the three arms' position error over the gap; the live estimate's
error with its ±3σ bounds per state; forecasts against the withheld measurements; NIS of
the filter over time. Also `report.html`: the same and more in one self-contained interactive
page (`report_html`); and `visual.mcap`: the Foxglove visual topics of the bag (`visual_mcap`),
to open in Foxglove with ``config/foxglove_layout.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any

import numpy as np

from ssa_fusion.apps import evaluate
from ssa_fusion.core import config, types
from ssa_fusion.ros import bagio

if TYPE_CHECKING:
    from matplotlib.figure import Figure

STATE_LABELS = ("x [km]", "y [km]", "z [km]", "vx [km/s]", "vy [km/s]", "vz [km/s]")


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Add the options of `ssa-fusion report` to `p`."""
    p.add_argument("bag", type=Path, help="rosbag2 directory (or .mcap file) to report on")
    p.add_argument("--out", type=Path, default=None, help="output directory (default: BAG_report)")
    p.add_argument("--scenario", default="",
                   help="evaluate with this paper scenario's estimator settings (default: "
                        "those recorded with the bag)")
    p.add_argument("--params-file", type=Path, default=None,
                   help="evaluate with the filter/surrogate settings of this ROS params YAML")


def run(args: argparse.Namespace) -> int:
    """Run `ssa-fusion report`; return the exit code (2 when the bag cannot be evaluated)."""
    out = args.out or args.bag.with_name(args.bag.name + "_report")
    try:
        data = evaluate.load(args.bag)
        ev = evaluate.evaluate(data, args.scenario, params_file=args.params_file)
        write(data, ev, out)
    except (bagio.BagError, ValueError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(evaluate.table(ev))
    if data.legacy_frame:
        print(data.frame_note(args.bag))
    print(f"\nwrote {out}/report.json, {out}/report.html, {out}/visual.mcap (open it in "
          "Foxglove with config/foxglove_layout.json) and plots")
    return 0


def summary(data: evaluate.BagData, ev: evaluate.Evaluation) -> dict[str, Any]:
    """Return what report.json (and live.json) hold of an evaluation."""
    g = ev.gap
    return {
        "arms": {str(name): {"epsilon": sc.epsilon, "pos_err_mean_km": sc.pos_err_mean_km,
                             "pos_err_final_km": sc.pos_err_final_km,
                             "nees_mean": sc.nees_mean}
                 for name, sc in g.scores.items()},
        "gap_epochs": len(g.t),
        "dmd_ekf_coverage": g.coverage,
        "dmd_ekf_propagated_epochs": g.predicted,
        "settings": ev.settings.origin,
        "estimator": config.to_dict(ev.settings.estimator),
        "message_counts": data.counts,
    }


def write(data: evaluate.BagData, ev: evaluate.Evaluation, out: Path) -> None:
    """Write report.json, the PNG plots, report.html and visual.mcap (Foxglove) into `out`."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "report.json").write_text(json.dumps(summary(data, ev), indent=2))
    plot_arms(ev, out / "arms.png")
    plot_sigma(data, out / "estimate_3sigma.png")
    plot_forecasts(data, out / "forecast_vs_withheld.png")
    plot_nis(data, out / "nis.png")
    from ssa_fusion.apps import report_html  # plotly: imported on first use, like the plots

    report_html.write(data, ev, out / "report.html", title=f"ssa_fusion report: {out.name}")
    from ssa_fusion.apps import visual_mcap  # foxglove-sdk, likewise

    stations = {s.name: s for s, _ in report_html.run_stations(ev.settings.estimator)}
    visual_mcap.write(data, out / "visual.mcap", stations)


def _plt() -> ModuleType:
    """Return the figure maker, `studies.plots` (`plots.subplots`).

    Imported on first use: `report` works without plots.
    """
    from ssa_fusion.studies import plots

    return plots


def save(fig: Figure, path: Path, dpi: int = 100) -> None:
    """Lay out and write `fig` as PNG (`plots.save`)."""
    from ssa_fusion.studies import plots

    plots.save(fig, path, dpi)


def plot_arms(ev: evaluate.Evaluation, path: Path) -> None:
    """Plot every arm's position error over the gap (km, log scale) to `path`."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 4))
    g = ev.gap
    hours = (g.t - g.t[0]) / 3600.0
    for arm, traj in g.arms.items():
        err = np.linalg.norm(traj.x[:, :3] - g.truth[:, :3], axis=1)
        ax.semilogy(hours, err, label=f"{arm} (ε={g.scores[arm].epsilon:.2e})")
    ax.set_xlabel("hours into the gap")
    ax.set_ylabel("position error [km]")
    ax.legend()
    ax.grid(True, which="both", alpha=0.3)
    save(fig, path, dpi=100)


def plot_sigma(data: evaluate.BagData, path: Path) -> None:
    """Plot the fused estimates' error per state with ±3σ to `path` (at epochs with a truth)."""
    plt = _plt()
    truth = {e.t: e.x for e in data.truth}
    est = [e for e in data.estimates if e.t in truth and e.update_source != types.UpdateSource.NONE]
    if not est:
        return
    t = np.array([e.t for e in est])
    err = np.array([e.x - truth[e.t] for e in est])
    sig = np.sqrt(np.array([np.diag(e.P) for e in est]))
    hours = (t - t[0]) / 3600.0
    fig, axes = plt.subplots(3, 2, figsize=(10, 7), sharex=True)
    for i, ax in enumerate(axes.T.ravel()):
        ax.plot(hours, err[:, i], lw=0.8, label="error")
        ax.plot(hours, 3 * sig[:, i], "r--", lw=0.8, label="±3σ")
        ax.plot(hours, -3 * sig[:, i], "r--", lw=0.8)
        ax.set_ylabel(STATE_LABELS[i])
        ax.grid(alpha=0.3)
    axes[0, 0].legend()
    for ax in axes[-1]:
        ax.set_xlabel("hours")
    save(fig, path, dpi=100)


def plot_forecasts(data: evaluate.BagData, path: Path) -> None:
    """Plot the forecasts against the withheld measurements to `path` (if any match)."""
    if not data.forecasts or not data.withheld:
        return
    plt = _plt()
    withheld = {m.t: m.z for m in data.withheld}
    f = [m for m in data.forecasts if m.t in withheld]
    if not f:
        return
    t = np.array([m.t for m in f])
    zf = np.array([m.z for m in f])
    zw = np.array([withheld[m.t] for m in f])
    kind = f[0].kind
    labels = (("range [km]", "azimuth [rad]", "elevation [rad]")
              if kind == types.Kind.RANGE_AZ_EL else ("x GCRF [km]", "y GCRF [km]", "z GCRF [km]"))
    fig, axes = plt.subplots(zf.shape[1], 1, figsize=(8, 6), sharex=True)
    for i, ax in enumerate(np.atleast_1d(axes)):
        ax.plot((t - t[0]) / 3600.0, zw[:, i], ".", ms=2, label="withheld (sensor)")
        ax.plot((t - t[0]) / 3600.0, zf[:, i], "-", lw=0.8, label="forecast")
        ax.set_ylabel(labels[i] if i < len(labels) else f"z[{i}]")
        ax.grid(alpha=0.3)
    np.atleast_1d(axes)[0].legend()
    np.atleast_1d(axes)[-1].set_xlabel("hours into the gap")
    save(fig, path, dpi=100)


def plot_nis(data: evaluate.BagData, path: Path) -> None:
    """Plot the filter's NIS over time, by update source, to `path`."""
    est = [e for e in data.estimates if e.update_source != types.UpdateSource.NONE]
    if not est:
        return
    plt = _plt()
    t = np.array([e.t for e in est])
    nis = np.array([e.nis for e in est])
    src = np.array([e.update_source for e in est])
    fig, ax = plt.subplots(figsize=(8, 3.5))
    for s, label in ((types.UpdateSource.SENSOR, "sensor"),
                     (types.UpdateSource.FORECAST, "forecast")):
        k = src == s
        ax.semilogy((t[k] - t[0]) / 3600.0, np.maximum(nis[k], 1e-6), ".", ms=2, label=label)
    ax.set_xlabel("hours")
    ax.set_ylabel("NIS")
    ax.legend()
    ax.grid(alpha=0.3, which="both")
    save(fig, path, dpi=100)
