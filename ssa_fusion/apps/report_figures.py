"""What the reports' PNG figures share: the figure maker, saving, lines broken at gaps, axes.

Both `report` (a simulated run: arms, ±3σ, forecasts, NIS) and `report_own` (your own data:
residuals, NIS, σ through the gaps) draw with `pyplot` and write with `save` (tests replace
`save` to look at the figures), and plot time series as hours after an epoch with no line
across a gap (`broken_line`). Times in s (Unix s), plotted in hours; angles given in rad,
shown in degrees.

A panel's scale is set by its bulk, not by one value far out: one residual of 600 km after a
first orbit fit once scaled a panel of metre residuals to ±600 km, a flat line.
`robust_limit` scales a symmetric panel by a high percentile of its values (never below a
floor such as the settled 3σ), and `mark_outside` draws the values beyond it as triangles on
the panel's edge, pointing out, labelled with how many and the largest.
"""

from __future__ import annotations

from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = ["beyond_legend", "broken_line", "hours", "mark_outside", "pyplot", "robust_limit",
           "save"]

BULK_PERCENTILE = 98.0
"""The percentile of |value| that sets a panel's scale (2 % of the values may lie beyond)."""
MARGIN = 1.3
"""A panel's half-height over that percentile (or over the floor)."""
EDGE = 0.97
"""Where on a panel's half-height the values beyond it are drawn."""
BEYOND = "beyond"
"""The group id (`gid`) of the triangles `mark_outside` draws."""


def pyplot() -> ModuleType:
    """Return the figure maker, `studies.plots` (`plots.subplots`).

    Imported on first use: the reports work without plots.
    """
    from ssa_fusion.studies import plots

    return plots


def save(fig: Figure, path: Path, dpi: int = 100) -> None:
    """Lay out and write `fig` as PNG (`plots.save`)."""
    from ssa_fusion.studies import plots

    plots.save(fig, path, dpi)


def hours(t: np.ndarray | list[float], t0: float) -> np.ndarray:
    """Return the epochs `t` (s) as hours after `t0` (s)."""
    return (np.asarray(t, dtype=float) - t0) / 3600.0


def broken_line(t_s: np.ndarray, y: np.ndarray, t0: float, break_s: float,
                angle: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Return (hours after `t0`, y) to plot as a line, NaN where it must not be drawn.

    A NaN between samples more than `break_s` (s) apart and, for an `angle` (rad, shown in
    deg), where it wraps (a jump over 180 deg): no line across a gap or across 0/360.
    """
    x = np.asarray(t_s, dtype=float)
    v = np.degrees(np.asarray(y, dtype=float)) if angle else np.asarray(y, dtype=float)
    cut = set((np.flatnonzero(np.diff(x) > break_s) + 1).tolist())
    if angle:
        cut |= set((np.flatnonzero(np.abs(np.diff(v)) > 180.0) + 1).tolist())
    where = sorted(cut)
    return np.insert(hours(x, t0), where, np.nan), np.insert(v, where, np.nan)


def robust_limit(values: np.ndarray, floor: float = 0.0) -> float:
    """Return the half-height of a symmetric panel of `values`: their bulk, with a margin.

    Parameters
    ----------
    values
        What the panel shows (its unit; NaN and infinities ignored).
    floor
        The least scale to show (the same unit), e.g. the settled 3σ; ignored when not
        finite.

    Returns
    -------
    float
        `MARGIN` times the larger of the `BULK_PERCENTILE` percentile of |values| (linear
        interpolation) and `floor`; 1 when both are 0 (nothing to scale by).
    """
    v = np.abs(np.asarray(values, dtype=float))
    v = v[np.isfinite(v)]
    bulk = float(np.percentile(v, BULK_PERCENTILE)) if v.size else 0.0
    least = float(floor) if np.isfinite(floor) else 0.0
    lim = MARGIN * max(bulk, least)
    return lim if lim > 0.0 else 1.0


def mark_outside(ax: Axes, x: np.ndarray, y: np.ndarray, lim: float, unit: str,
                 color: str = "tab:red") -> int:
    """Set `ax` to ±`lim`; draw the points of (`x`, `y`) beyond it on its edge; return how many.

    Each such point is a triangle at `EDGE` × ±`lim`, pointing away from the middle, all in
    one legend entry "N beyond ±lim unit (largest v)", v the farthest value, signed.

    Parameters
    ----------
    ax
        The panel.
    x, y
        The points (x as drawn, e.g. hours; y in `unit`).
    lim
        The panel's half-height (`unit`), e.g. `robust_limit` of `y`.
    unit
        The unit of `y` as shown in the label (e.g. "km", "arcsec").
    color
        The triangles' colour.
    """
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    out = np.isfinite(y) & (np.abs(y) > lim)
    ax.set_ylim(-lim, lim)
    n = int(out.sum())
    if not n:
        return 0
    worst = float(y[out][np.argmax(np.abs(y[out]))])
    label: str | None = f"{n} beyond ±{lim:.3g} {unit} (largest {worst:.3g})"
    for sign, marker in ((1.0, "^"), (-1.0, "v")):
        k = out & (np.sign(y) == sign)
        if k.any():
            ax.plot(x[k], np.full(int(k.sum()), sign * EDGE * lim), marker, ms=6, color=color,
                    linestyle="None", clip_on=False, label=label, gid=BEYOND)
            label = None  # one legend entry for both edges
    return n


def beyond_legend(ax: Axes) -> None:
    """Give `ax` a legend of the `mark_outside` triangles only (none when it has none).

    For a panel under another that holds the figure's legend: it says only what is its own.
    """
    marks = [ln for ln in ax.get_lines()
             if ln.get_gid() == BEYOND and not str(ln.get_label()).startswith("_")]
    if marks:
        ax.legend(handles=marks, fontsize=7, loc="upper right")
