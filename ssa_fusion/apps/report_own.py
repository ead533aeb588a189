"""`ssa-fusion report BAG` for a bag without an outage to score arms over: your own data.

A TDM imported with `import tdm` and estimated with `replay --offline [--smooth]` has no truth
and no outage to score against; a simulation whose outage fell where no pass was has its
truth but no outage. What is checked (the numbers from `evaluation.residuals`):

* ``residuals.png``: per channel, the pre-fit residual (measurement minus the filter's
  predicted measurement before the update) in the channel's units (range m, angles arcsec,
  positions m), points coloured by station, against ±3σ of the innovation covariance S and
  ±3σ of the measurement noise R;
* ``nis.png``: the NIS the filter published for each fused real measurement against the
  two-sided 95 % χ² band of the measurement's dimension, the fraction inside in the legend;
* ``position_sigma.png``: the 1-σ position uncertainty √trace(P_rr) (km) of the filter's
  estimates over time (fused, and its predictions through the gaps), of the smoothed
  estimates when the bag holds ``/ssa/estimate_smoothed``; the gaps between passes shaded;
* the passes table (per station pass: UTC span, measurements fused and not, largest
  elevation, RMS of the normalised residuals), printed and in ``report.html`` (the plots
  and tables in one self-contained page) and ``report.json``;
* with a truth on ``/ssa/truth`` (a simulation's bag): the position error after each pass
  and between the passes (`evaluate.truth_scores`), printed and in ``report.json``
  (``position_error``).

No line is drawn between samples further apart than `residuals.PASS_BREAK_S` (a pass break).
"""

from __future__ import annotations

import base64
import html
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ssa_fusion.apps import evaluate, report_figures
from ssa_fusion.apps.report_figures import broken_line, hours, mark_outside, robust_limit
from ssa_fusion.core.base import types
from ssa_fusion.core.gaps.estimator import uncovered_stations
from ssa_fusion.evaluation import passes as passes_
from ssa_fusion.evaluation import residuals as res_
from ssa_fusion.evaluation.gap_scores import GapScores
from ssa_fusion.evaluation.residuals import PASS_BREAK_S
from ssa_fusion.formats.ccsds import common as ccsds_format

if TYPE_CHECKING:
    from matplotlib.axes import Axes

ARCSEC_PER_RAD = 180.0 / math.pi * 3600.0
CHANNELS: dict[int, tuple[tuple[str, str, float], ...]] = {
    types.Kind.RANGE_AZ_EL: (("range", "m", 1000.0), ("azimuth", "arcsec", ARCSEC_PER_RAD),
                             ("elevation", "arcsec", ARCSEC_PER_RAD)),
    types.Kind.RA_DEC: (("right ascension", "arcsec", ARCSEC_PER_RAD),
                        ("declination", "arcsec", ARCSEC_PER_RAD)),
    types.Kind.POSITION: (("x GCRF", "m", 1000.0), ("y GCRF", "m", 1000.0),
                          ("z GCRF", "m", 1000.0)),
}
"""Per measurement kind, each channel's (name, unit shown, factor from the core's unit)."""
PLOTS = ("residuals.png", "nis.png", "position_sigma.png")
NIS_REPRODUCED = 1e-6
"""Relative: the recomputed residuals' NIS against the filter's published one (rounding)."""


@dataclass
class OwnReport:
    """What the report of a bag without truth shows."""

    settings: evaluate.Settings
    residuals: list[res_.Residual]
    published: list[res_.Nis]
    """The NIS the filter published with each fused real measurement."""
    nis: res_.NisSummary
    passes: list[res_.PassRow]
    gaps: list[tuple[float, float]]
    unknown_stations: list[str]
    """Stations of the measurements the settings do not know (no residuals for them)."""
    truth: int = 0
    """The states on /ssa/truth (a simulation's bag): what the estimates are judged against."""
    after_passes: passes_.PassReport | None = None
    """With a truth: the position error after each pass and at every truth epoch."""
    between: GapScores | None = None
    """With a truth: what the filter published between passes, scored."""

    def truth_lines(self) -> list[str]:
        """Return the position error against the truth as lines ([] without a truth)."""
        if self.after_passes is None:
            return []
        lines = [f"against the bag's /ssa/truth ({self.truth} states):",
                 self.after_passes.table()]
        if self.between is not None and self.between.gap_epochs:
            lines.append(evaluate.between_line(self.between))
        return lines

    def position_error(self) -> dict[str, Any] | None:
        """Return report.json's position error against the truth (None without one)."""
        return evaluate.position_error(self.after_passes, self.between, self.truth)


def build(data: evaluate.BagData, settings: evaluate.Settings) -> OwnReport:
    """Compute the report's numbers (`evaluation.residuals`) for `data` with `settings`."""
    c = settings.estimator
    real = [m for m in data.measurements if m.source == types.Source.SENSOR]
    res = res_.residuals(c, data.estimates, real)
    published = res_.published_nis(data.estimates, real)
    fused = [e.t for e in data.estimates if e.update_source == types.UpdateSource.SENSOR]
    unknown = ([] if c.kind == types.Kind.POSITION
               else uncovered_stations(c, {m.frame_id for m in real}))
    after, between = evaluate.truth_scores(data, c)
    return OwnReport(settings, res, published, res_.nis_summary(published),
                     res_.pass_rows(real, fused, res), res_.gaps(real), unknown,
                     len(data.truth), after, between)


def utc(t: float) -> str:
    """Unix seconds as ISO UTC to the second."""
    return ccsds_format.format_epoch(round(t))[:19]


PASS_COLUMNS = ("pass", "station", "start (UTC)", "end (UTC)", "fused", "not fused",
                "max elevation [deg]", "residual RMS [σ]")


def pass_cells(rep: OwnReport) -> list[list[str]]:
    """Return the passes table's cells (`PASS_COLUMNS`), one row per pass, formatted."""
    return [[str(i), p.station, utc(p.t_start), utc(p.t_end), str(p.fused), str(p.not_fused),
             "–" if math.isnan(p.max_elevation_deg) else f"{p.max_elevation_deg:.1f}",
             "–" if math.isnan(p.rms_normalised) else f"{p.rms_normalised:.2f}"]
            for i, p in enumerate(rep.passes, start=1)]


def notes(rep: OwnReport) -> list[str]:
    """Return the lines under the passes table: NIS, residual RMS, what was computed how."""
    n = rep.nis
    out = []
    if n.n:
        bands = ", ".join(f"[{lo:.2f}, {hi:.2f}] ({dof} dof)" for dof, (lo, hi) in
                          sorted(n.band.items()))
        out.append(f"NIS inside the 95 % χ² band {bands}: {100 * n.fraction:.1f} % of "
                   f"{n.n} fused measurements (a consistent filter: about 95 %)")
    else:
        out.append("no fused measurement with an innovation: no NIS")
    if rep.residuals:
        norm = np.concatenate([r.normalised for r in rep.residuals])
        per = ", ".join(
            f"{channel[0]} {v:.2f}" for same, channels in _by_kind(rep.residuals)
            for channel, v in zip(channels, np.sqrt(np.mean(
                np.array([r.normalised for r in same]) ** 2, axis=0)), strict=True))
        out.append(f"residual RMS in units of the innovation σ: {np.sqrt(np.mean(norm ** 2)):.2f}"
                   f" over all channels ({per}; a consistent filter: about 1)")
        worst = max(abs(r.nis / r.nis_filter - 1.0) for r in rep.residuals)
        verdict = ("passed" if worst <= NIS_REPRODUCED else
                   f"FAILED (more than {NIS_REPRODUCED:.0e}): the residuals recomputed here "
                   "are not the filter's; are the settings the run's?")
        out.append(f"residuals: pre-fit (measurement minus the filter's predicted measurement "
                   f"before its update); check that their NIS reproduces the filter's "
                   f"published one: {verdict} ({worst:.1e} relative)")
    if rep.unknown_stations:
        out.append(f"no residuals for station(s) {', '.join(rep.unknown_stations)}: the "
                   f"settings do not take them (give their sites file with --sites)")
    if rep.gaps:
        h = [(b - a) / 3600.0 for a, b in rep.gaps]
        out.append(f"gaps between passes (measurements more than {PASS_BREAK_S:g} s apart): "
                   f"{len(h)}, {min(h):.2f} to {max(h):.2f} h")
    out.append(f"settings: {rep.settings.origin}")
    return out


def table(rep: OwnReport) -> str:
    """Markdown: the passes table, then the notes, then the error against a truth."""
    rows = ["| " + " | ".join(PASS_COLUMNS) + " |", "|" + "---|" * len(PASS_COLUMNS)]
    rows += ["| " + " | ".join(cells) + " |" for cells in pass_cells(rep)]
    truth = rep.truth_lines()
    return ("\n".join(rows) + "\n\n" + "\n".join(notes(rep))
            + ("\n\n" + "\n".join(truth) if truth else ""))


def summary(data: evaluate.BagData, rep: OwnReport) -> dict[str, Any]:
    """Return what report.json holds."""
    return {
        "truth": rep.after_passes is not None,
        "position_error": rep.position_error(),
        "nis_inside_95": rep.nis.fraction if rep.nis.n else None,
        "nis_count": rep.nis.n,
        "residual_rms_sigma": (float(np.sqrt(np.mean(np.concatenate(
            [r.normalised for r in rep.residuals]) ** 2))) if rep.residuals else None),
        "passes": [{"station": p.station, "start": p.t_start, "end": p.t_end, "fused": p.fused,
                    "not_fused": p.not_fused,
                    "max_elevation_deg": None if math.isnan(p.max_elevation_deg)
                    else p.max_elevation_deg,
                    "residual_rms_sigma": None if math.isnan(p.rms_normalised)
                    else p.rms_normalised} for p in rep.passes],
        "settings": rep.settings.origin,
        "message_counts": data.counts,
    }


def write(data: evaluate.BagData, rep: OwnReport, out: Path, title: str) -> None:
    """Write the PNGs, report.json and report.html into `out`."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "report.json").write_text(json.dumps(summary(data, rep), indent=2))
    for name in PLOTS:  # an earlier report's plot that this one does not draw
        (out / name).unlink(missing_ok=True)
    t0 = min(m.t for m in data.measurements)
    plot_residuals(rep, t0, out / "residuals.png")
    plot_nis(rep, t0, out / "nis.png")
    plot_sigma(data, rep, t0, out / "position_sigma.png")
    page(rep, out, title)


def shade_gaps(ax: Axes, rep: OwnReport, t0: float) -> None:
    """Shade the gaps between passes on `ax` (hours after `t0`), labelled once."""
    for i, (a, b) in enumerate(rep.gaps):
        ax.axvspan(*hours([a, b], t0), color="0.9", zorder=0,
                   label=f"gap between passes (> {PASS_BREAK_S:g} s)" if i == 0 else None)


def above(ax: Axes) -> None:
    """Put the legend of `ax` in one row above it, off the data."""
    ax.legend(fontsize=7, ncol=4, loc="lower left", bbox_to_anchor=(0.0, 1.0),
              frameon=False)


def _xlabel(t0: float) -> str:
    return f"hours since {utc(t0)} UTC [h]"


def plot_residuals(rep: OwnReport, t0: float, path: Path) -> None:
    """Plot per channel the pre-fit residuals by station against ±3σ of S and of R.

    One panel per channel of every measurement kind in the bag (a radar's range, azimuth
    and elevation, then a telescope's right ascension and declination, ...). Each panel
    scaled by the bulk of its residuals, at least the settled 3σ of S; residuals beyond are
    marked on its edge (`report_figures.mark_outside`).
    """
    if not rep.residuals:
        return
    plt = report_figures.pyplot()
    panels = [(same, i, channel) for same, channels in _by_kind(rep.residuals)
              for i, channel in enumerate(channels)]
    fig, axes = plt.subplots(len(panels), 1, figsize=(9, 2.4 * len(panels) + 0.8),
                             sharex=True)
    for k, (ax, (same, i, channel)) in enumerate(zip(np.atleast_1d(axes), panels,
                                                     strict=True)):
        residual_panel(ax, rep, same, i, channel, t0)
        if k:  # the first panel holds the figure's legend
            report_figures.beyond_legend(ax)
    above(np.atleast_1d(axes)[0])
    np.atleast_1d(axes)[-1].set_xlabel(_xlabel(t0))
    fig.suptitle("Pre-fit residuals (measurement − filter's prediction before the update)")
    report_figures.save(fig, path, dpi=100)


def _by_kind(residuals: list[res_.Residual]) -> list[tuple[list[res_.Residual],
                                                          tuple[tuple[str, str, float], ...]]]:
    """Group `residuals` by measurement kind, in order of first appearance.

    Each group comes with its kind's channels (name, unit shown, factor from the core's
    unit).
    """
    out = []
    for kind in dict.fromkeys(r.kind for r in residuals):
        same = [r for r in residuals if r.kind == kind]
        out.append((same, CHANNELS.get(kind, tuple((f"z[{i}]", "-", 1.0)
                                                   for i in range(len(same[0].y))))))
    return out


def residual_panel(ax: Axes, rep: OwnReport, same: list[res_.Residual], i: int,
                   channel: tuple[str, str, float], t0: float) -> int:
    """Draw channel `i` of the residuals `same` (one kind) on `ax`: points, ±3σ, scale.

    `channel` is (name, unit shown, factor from the core's unit); returns how many
    residuals lie beyond the panel (marked on its edge).
    """
    name, unit, f = channel
    shade_gaps(ax, rep, t0)
    t = np.array([r.t for r in same])
    y = np.array([r.y[i] for r in same]) * f
    s3 = 3 * np.array([r.sigma[i] for r in same]) * f
    r3 = 3 * np.array([r.sigma_r[i] for r in same]) * f
    for sign in (1, -1):
        ax.plot(*broken_line(t, sign * s3, t0, PASS_BREAK_S), "k--", lw=0.8,
                label="±3σ innovation (S = HPHᵀ + R)" if sign == 1 else None)
        ax.plot(*broken_line(t, sign * r3, t0, PASS_BREAK_S), ":", color="tab:red",
                lw=0.8, label="±3σ measurement (R)" if sign == 1 else None)
    for j, st in enumerate(sorted({r.station for r in same})):
        k = np.array([r.station == st for r in same])
        ax.plot(hours(t[k], t0), y[k], ".", ms=3, color=f"C{j}", label=st)
    ax.set_ylabel(f"{name} [{unit}]")
    ax.grid(alpha=0.3)
    # the scale of the residuals' bulk and of the settled σ, not of one residual far out
    # nor of the first σ after the initial orbit determination
    return mark_outside(ax, hours(t, t0), y, robust_limit(y, float(np.median(s3))), unit,
                        color="black")


def plot_nis(rep: OwnReport, t0: float, path: Path) -> None:
    """Plot the published NIS of each fused real measurement against its 95 % χ² band."""
    if not rep.published:
        return
    plt = report_figures.pyplot()
    fig, ax = plt.subplots(figsize=(9, 3.5))
    shade_gaps(ax, rep, t0)
    t = np.array([v.t for v in rep.published])
    nis = np.array([v.nis for v in rep.published])
    x0, x1 = float(hours([t[0]], t0)[0]), float(hours([t[-1]], t0)[0])
    for dof, (lo, hi) in sorted(rep.nis.band.items()):
        ax.fill_between([x0, x1], lo, hi, color="tab:green", alpha=0.15,
                        label=f"95 % χ² band [{lo:.2f}, {hi:.2f}] ({dof} dof)")
    stations = sorted({v.station for v in rep.published})
    for j, st in enumerate(stations):
        k = np.array([v.station == st for v in rep.published])
        ax.plot(hours(t[k], t0), nis[k], ".", ms=3, color=f"C{j}", label=st)
    ax.set_yscale("log")
    ax.set_xlabel(_xlabel(t0))
    ax.set_ylabel("NIS [-]")
    ax.set_title(f"NIS of the fused measurements: {100 * rep.nis.fraction:.1f} % of "
                 f"{rep.nis.n} inside the 95 % band", pad=28)
    above(ax)
    ax.grid(alpha=0.3, which="both")
    report_figures.save(fig, path, dpi=100)


def plot_sigma(data: evaluate.BagData, rep: OwnReport, t0: float, path: Path) -> None:
    """Plot the 1-σ position uncertainty (km, log) of the estimates, gaps shaded.

    Estimates that fused a measurement (a line within each pass), those that fused a gap
    forecast (green), the filter's predictions through the gaps (markers, dotted), and the
    smoothed estimates when the bag holds them (dashed).
    """
    fused = [e for e in data.estimates if e.update_source == types.UpdateSource.SENSOR]
    forecast = [e for e in data.estimates if e.update_source == types.UpdateSource.FORECAST]
    if not fused and not forecast:
        return
    plt = report_figures.pyplot()
    fig, ax = plt.subplots(figsize=(9, 4))
    shade_gaps(ax, rep, t0)
    if fused:
        t, s = res_.position_sigma(fused)
        ax.plot(*broken_line(t, s, t0, PASS_BREAK_S), "-", lw=1.2, color="tab:blue",
                label="filter, epochs of fused measurements")
    if forecast:
        t, s = res_.position_sigma(forecast)
        ax.plot(*broken_line(t, s, t0, PASS_BREAK_S), "-", lw=1.0, color="tab:green",
                label="filter, epochs of fused gap forecasts")
    predicted = [e for e in data.estimates if e.update_source == types.UpdateSource.NONE]
    if predicted:
        t, s = res_.position_sigma(predicted)
        ax.plot(*broken_line(t, s, t0, PASS_BREAK_S), ":o", ms=3, lw=0.8, color="tab:blue",
                label="filter, predicted through the gaps")
    if data.smoothed:
        t, s = res_.position_sigma(data.smoothed)
        ax.plot(*broken_line(t, s, t0, PASS_BREAK_S), "--", lw=1.2, color="tab:orange",
                label="smoothed (/ssa/estimate_smoothed)")
    ax.set_yscale("log")
    ax.set_xlabel(_xlabel(t0))
    ax.set_ylabel("1-σ position √trace(P_rr) [km]")
    ax.set_title("Position uncertainty through the passes and gaps", pad=28)
    above(ax)
    ax.grid(alpha=0.3, which="both")
    report_figures.save(fig, path, dpi=100)


def page(rep: OwnReport, out: Path, title: str) -> None:
    """Write report.html: the passes table, its notes and the PNGs inlined (one file)."""
    head = "".join(f"<th>{html.escape(h)}</th>" for h in PASS_COLUMNS)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in row) + "</tr>"
                   for row in pass_cells(rep))
    judged = (f"against the bag's /ssa/truth ({rep.truth} states), and by its residuals, "
              "NIS and covariance" if rep.after_passes is not None else
              "by its residuals, NIS and covariance (the bag has no /ssa/truth)")
    parts = [f"<h1>{html.escape(title)}</h1>",
             f"<p class=\"note\">The filter judged {html.escape(judged)}.</p>",
             "<h2>Passes</h2>",
             f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>",
             *(f'<p class="note">{html.escape(n)}</p>' for n in notes(rep))]
    if rep.after_passes is not None:
        parts += ["<h2>Position error against the truth</h2>",
                  f"<pre>{html.escape(chr(10).join(rep.truth_lines()))}</pre>"]
    for name in PLOTS:
        png = out / name
        if png.exists():
            b64 = base64.b64encode(png.read_bytes()).decode("ascii")
            parts.append(f'<p><img alt="{name}" src="data:image/png;base64,{b64}"></p>')
    from ssa_fusion.apps.report_html import STYLE

    (out / "report.html").write_text(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
        f"<title>{html.escape(title)}</title>{STYLE}</head>\n<body>\n" + "\n".join(parts)
        + "\n</body></html>\n", encoding="utf-8")
