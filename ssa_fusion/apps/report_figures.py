"""What the reports' PNG figures share: the figure maker, saving, lines broken at gaps.

Both `report` (a simulated run: arms, ±3σ, forecasts, NIS) and `report_own` (your own data:
residuals, NIS, σ through the gaps) draw with `pyplot` and write with `save` (tests replace
`save` to look at the figures), and plot time series as hours after an epoch with no line
across a gap (`broken_line`). Times in s (Unix s), plotted in hours; angles given in rad,
shown in degrees.
"""

from __future__ import annotations

from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["broken_line", "hours", "pyplot", "save"]


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
