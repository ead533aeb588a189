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
from typing import TYPE_CHECKING, Any

import numpy as np

from ssa_fusion.apps import evaluate, replay_catalog, report_figures
from ssa_fusion.apps.args import add_settings, add_sites
from ssa_fusion.apps.filter_setup import DataMix
from ssa_fusion.apps.heartbeat import working
from ssa_fusion.apps.report_figures import (
    beyond_legend,
    broken_line,
    hours,
    mark_outside,
    robust_limit,
)
from ssa_fusion.core.base import metrics, types
from ssa_fusion.core.gaps import estimator as config
from ssa_fusion.formats import sites as site_file
from ssa_fusion.ros import bag_runs, bagio
from ssa_fusion.ros.laser_bag import is_laser
from ssa_fusion.ros.topics import TOPIC_CONFIG

if TYPE_CHECKING:
    from matplotlib.axes import Axes

STATE_UNITS = ("km",) * 3 + ("km/s",) * 3
STATE_LABELS = tuple(f"{name} [{unit}]" for name, unit in
                     zip(("x", "y", "z", "vx", "vy", "vz"), STATE_UNITS, strict=True))
SETTLED_PERCENTILE = 95.0
"""The percentile of a state's 3σ over the run taken as its settled 3σ: a panel's least
half-height (the first sigmas after the initial orbit determination lie above it)."""


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Add the options of `ssa-fusion report` to `p`."""
    p.add_argument("bag", type=Path, help="rosbag2 directory (or .mcap file) to report on")
    p.add_argument("--out", type=Path, default=None, help="output directory (default: BAG_report)")
    add_settings(p, "evaluate", "those recorded with the bag")
    add_sites(p, "stations of your own that the bag's measurements name (their residuals "
                 "need the stations' positions)")


def run(args: argparse.Namespace) -> int:
    """Run `ssa-fusion report`; return the exit code (2 when the bag cannot be evaluated).

    A bag without simulated truth or outage (your own measurements, replayed) gets the
    report of `report_own`: residuals, NIS, σ through the gaps, passes; a catalog's bag
    (several objects, unlabelled detections, or the catalog_filter's settings) that of
    `report_catalog`: each object scored on its own rows; a laser-ranging bag that of
    `report_laser`: the fit's residuals per station and pass, biases, NIS, the reference.
    """
    out = args.out or args.bag.with_name(args.bag.name + "_report")
    try:
        bag_runs.check_one_run(args.bag)  # a bag of two runs is no run to score
        # a catalog's bag (`replay_catalog.catalog_reason`, as `replay` tells it) is scored
        # object by object, never as one object's run; its recorded catalog_filter
        # settings tell it without holding its measurements
        telling = list(bagio.read_bag(args.bag, topics=[TOPIC_CONFIG]))
        catalog = replay_catalog.catalog_reason(telling)
        if catalog is None:
            telling = list(bagio.read_bag(args.bag, topics=replay_catalog.TELLING))
            catalog = replay_catalog.catalog_reason(telling)
    except (bagio.BagError, ValueError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if catalog is not None:
        from ssa_fusion.apps import report_catalog

        return report_catalog.run(args, telling, catalog, out)
    if is_laser(telling):
        from ssa_fusion.apps import report_laser

        return report_laser.run(args, list(bagio.read_records(args.bag)), out)
    del telling
    try:
        data = evaluate.load(args.bag)
        evaluate.require_outage(data)
        with working("report", "scoring the arms over the outage"):
            ev = evaluate.evaluate(data, args.scenario, params_file=args.params_file,
                                   setup=args.setup)
        write(data, ev, out)
    except evaluate.NoTruthError as exc:
        return run_own(args, data, out, str(exc))
    except (bagio.BagError, ValueError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(evaluate.table(ev))
    if data.legacy_frame:
        print(data.frame_note(args.bag))
    print(f"\nwrote {out}/report.json, {out}/report.html, {out}/visual.mcap (open it in "
          "Foxglove with config/foxglove_layout.json) and plots")
    return 0


def run_own(args: argparse.Namespace, data: evaluate.BagData, out: Path, why: str) -> int:
    """Report on a bag without simulated truth (`report_own`); return the exit code.

    Its estimates are needed: a bag of measurements only is refused (exit 2) saying to
    replay it first. The settings are chosen as `replay` chooses them (with ``--sites``).
    """
    from ssa_fusion.apps import report_own

    if not any(e.update_source != types.UpdateSource.NONE for e in data.estimates):
        print(f"error: {args.bag}: {why}, and no estimates of a filter to report on: run "
              f"`ssa-fusion replay {args.bag} --offline --smooth` (add --sites FILE for "
              f"stations of your own) and report on the bag it writes", file=sys.stderr)
        return 2
    try:
        sites = site_file.load_stations(args.sites) if args.sites else ()
        chosen = evaluate.settings_for_bag(data.config, DataMix.of(data.measurements),
                                           args.scenario, args.params_file, sites,
                                           getattr(args, "setup", None))
        with working(getattr(args, "command", "report"),
                     "judging the estimates and drawing the plots"):
            rep = report_own.build(data, chosen)
            report_own.write(data, rep, out, title=f"ssa_fusion report: {out.name}")
    except (ValueError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    judged = (f"judged against its /ssa/truth ({len(data.truth)} states) and by its residuals, "
              f"NIS and covariance" if rep.after_passes is not None else
              "no /ssa/truth: the filter judged by its residuals, NIS and covariance")
    print(f"{args.bag}: {why}; {judged}\n")
    print(report_own.table(rep))
    drawn = [name for name in report_own.PLOTS if (out / name).exists()]
    print(f"\nwrote {out}/report.json, {out}/report.html"
          + (f" and plots ({', '.join(drawn)})" if drawn else ""))
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
        "position_error": evaluate.position_error(ev.passes, ev.between, len(data.truth)),
        "settings": ev.settings.origin,
        "estimator": config.to_dict(ev.settings.estimator),
        "message_counts": data.counts,
    }


def write(data: evaluate.BagData, ev: evaluate.Evaluation, out: Path,
          command: str = "report") -> None:
    """Write report.json, the PNG plots, report.html and visual.mcap (Foxglove) into `out`.

    Each of the three steps says itself on stderr (`heartbeat.working`), as `command`.
    """
    out.mkdir(parents=True, exist_ok=True)
    (out / "report.json").write_text(json.dumps(summary(data, ev), indent=2))
    with working(command, "drawing the plots"):
        plot_arms(ev, out / "arms.png")
        plot_sigma(data, out / "estimate_3sigma.png")
        plot_forecasts(data, out / "forecast_vs_withheld.png")
        plot_nis(data, out / "nis.png")
    from ssa_fusion.apps import report_html  # plotly: imported on first use, like the plots

    with working(command, "writing report.html"):
        report_html.write(data, ev, out / "report.html", title=f"ssa_fusion report: {out.name}")
    from ssa_fusion.apps import visual_mcap  # foxglove-sdk, likewise

    stations = {s.name: s for s, _ in report_html.run_stations(ev.settings.estimator)}
    with working(command, "writing visual.mcap (the Foxglove file)"):
        visual_mcap.write(data, out / "visual.mcap", stations)


GAP_BREAK_S = 1800.0
"""Samples further apart than this (s) are not joined by a line: a gap between passes, not a
trend."""


def outage_hours(data: evaluate.BagData, t0: float) -> tuple[float, float] | None:
    """Return the scheduled outage (first to last withheld measurement) in h after `t0`."""
    if not data.withheld:
        return None
    w = [m.t for m in data.withheld]
    return (min(w) - t0) / 3600.0, (max(w) - t0) / 3600.0


def shade(ax: Axes, span: tuple[float, float] | None) -> None:
    """Shade the outage `span` (h) on `ax`, labelled once."""
    if span is not None:
        ax.axvspan(*span, color="0.85", zorder=0, label="outage (withheld)")


def plot_arms(ev: evaluate.Evaluation, path: Path) -> None:
    """Plot every arm's position error over the gap (km, log scale) to `path`."""
    plt = report_figures.pyplot()
    fig, ax = plt.subplots(figsize=(8, 4))
    g = ev.gap
    hours = (g.t - g.t[0]) / 3600.0
    for arm, traj in g.arms.items():
        err = np.linalg.norm(traj.x[:, :3] - g.truth[:, :3], axis=1)
        ax.semilogy(hours, err, label=f"{arm} (ε={g.scores[arm].epsilon:.2e})")
    ax.set_xlabel("hours into the gap [h]")
    ax.set_ylabel("position error [km]")
    ax.set_title("Position error of every arm over the gap")
    ax.legend(fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    report_figures.save(fig, path, dpi=100)


def plot_sigma(data: evaluate.BagData, path: Path) -> None:
    """Plot the fused estimates' error per state with ±3σ to `path` (at epochs with a truth).

    No line joins epochs further apart than `GAP_BREAK_S` (the gaps between passes); the
    outage is shaded. Each panel is scaled by the bulk of its errors, at least the settled
    3σ (`robust_limit`); errors beyond are marked on its edge (`mark_outside`).
    """
    plt = report_figures.pyplot()
    truth = {e.t: e.x for e in data.truth}
    est = [e for e in data.estimates if e.t in truth and e.update_source != types.UpdateSource.NONE]
    if not est:
        return
    t = np.array([e.t for e in est])
    err = np.array([e.x - truth[e.t] for e in est])
    sig = np.sqrt(np.array([np.diag(e.P) for e in est]))
    span = outage_hours(data, float(t[0]))
    fig, axes = plt.subplots(3, 2, figsize=(10, 7), sharex=True)
    for i, ax in enumerate(axes.T.ravel()):
        shade(ax, span)
        ax.plot(*broken_line(t, err[:, i], t[0], GAP_BREAK_S), lw=0.8, label="error")
        h, three = broken_line(t, 3 * sig[:, i], t[0], GAP_BREAK_S)
        ax.plot(h, three, "r--", lw=0.8, label="±3σ")
        ax.plot(h, -three, "r--", lw=0.8)
        # the scale of the run's bulk, not of the initial orbit determination's first
        # sigmas nor of one error far out (marked on the edge)
        lim = robust_limit(err[:, i], float(np.nanpercentile(3 * sig[:, i], SETTLED_PERCENTILE)))
        mark_outside(ax, hours(t, t[0]), err[:, i], lim, STATE_UNITS[i])
        if i:  # the first panel holds the figure's legend
            beyond_legend(ax)
        ax.set_ylabel(STATE_LABELS[i])
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("hours since the first estimate [h]")
    fig.suptitle("Error of the fused estimates (GCRF) against their ±3σ")
    report_figures.save(fig, path, dpi=100)


FORECAST_LABELS = {types.Kind.RANGE_AZ_EL: ("range [km]", "azimuth [deg]", "elevation [deg]"),
                   types.Kind.RA_DEC: ("right ascension [deg]", "declination [deg]"),
                   types.Kind.POSITION: ("x GCRF [km]", "y GCRF [km]", "z GCRF [km]")}
"""Axis labels of a measurement's channels, by kind (angles shown in degrees)."""


def _is_angle(kind: int, i: int) -> bool:
    """Return whether channel `i` of a measurement of `kind` is an angle (rad)."""
    return i in {types.Kind.RANGE_AZ_EL: (1, 2), types.Kind.RA_DEC: (0, 1)}.get(
        types.Kind(kind), ())


def plot_forecasts(data: evaluate.BagData, path: Path) -> None:
    """Plot the forecasts against the withheld measurements to `path` (if any match).

    Angles in degrees, without lines across their wrap or across gaps; a forecast line
    stops where the forecasts do (no line over withheld epochs without a forecast: broken
    where forecasts are more than 1.5 withheld spacings apart).
    """
    if not data.forecasts or not data.withheld:
        return
    plt = report_figures.pyplot()
    withheld = {m.t: m.z for m in data.withheld}
    f = [m for m in data.forecasts if m.t in withheld]
    if not f:
        return
    t = np.array([m.t for m in f])
    zf = np.array([m.z for m in f])
    kind = f[0].kind
    tw = np.array(sorted(m.t for m in data.withheld if m.kind == kind))
    zw = np.array([withheld[x] for x in tw])
    step = 1.5 * float(np.median(np.diff(tw))) if len(tw) > 1 else GAP_BREAK_S
    labels = FORECAST_LABELS.get(types.Kind(kind), ())
    fig, axes = plt.subplots(zf.shape[1], 1, figsize=(8, 6), sharex=True)
    for i, ax in enumerate(np.atleast_1d(axes)):
        angle = _is_angle(kind, i)
        ax.plot(*broken_line(tw, zw[:, i], tw[0], GAP_BREAK_S, angle), ".", ms=2,
                label="withheld (sensor)")
        ax.plot(*broken_line(t, zf[:, i], tw[0], min(step, GAP_BREAK_S), angle), "-",
                lw=0.8, label="forecast (where one was published)")
        ax.set_ylabel(labels[i] if i < len(labels) else f"z[{i}]")
        ax.grid(alpha=0.3)
    np.atleast_1d(axes)[0].legend(fontsize=8)
    np.atleast_1d(axes)[-1].set_xlabel("hours into the gap [h]")
    fig.suptitle("Forecasts against the measurements withheld in the outage")
    report_figures.save(fig, path, dpi=100)


def plot_nis(data: evaluate.BagData, path: Path) -> None:
    """Plot the filter's NIS over time, by update source, against its 95 % χ² band.

    Epochs without an innovation (NIS 0: the initial orbit determination) are left out; the
    outage is shaded.
    """
    est = [e for e in data.estimates if e.update_source != types.UpdateSource.NONE and e.nis > 0]
    if not est:
        return
    plt = report_figures.pyplot()
    t = np.array([e.t for e in est])
    nis = np.array([e.nis for e in est])
    src = np.array([e.update_source for e in est])
    dof = len(data.measurements[0].z) if data.measurements else 3
    lo, hi = metrics.chi2_bounds(dof)
    fig, ax = plt.subplots(figsize=(8, 3.5))
    shade(ax, outage_hours(data, float(t[0])))
    end = (t[-1] - t[0]) / 3600.0
    ax.fill_between([0.0, end], lo, hi, color="tab:green", alpha=0.15,
                    label=f"95 % χ² band [{lo:.2f}, {hi:.2f}] ({dof} dof)")
    for s, label in ((types.UpdateSource.SENSOR, "sensor update"),
                     (types.UpdateSource.FORECAST, "forecast update")):
        k = src == s
        if k.any():
            ax.semilogy((t[k] - t[0]) / 3600.0, nis[k], ".", ms=2, label=label)
    ax.set_yscale("log")
    ax.set_xlabel("hours since the first update [h]")
    ax.set_ylabel("NIS [-]")
    ax.set_title("Normalised innovation squared of the filter")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")
    report_figures.save(fig, path, dpi=100)
