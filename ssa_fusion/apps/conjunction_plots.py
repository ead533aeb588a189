"""The encounter plane of each likely approach of a catalog's bag, one PNG each.

For the approaches `conjunction_table` lists (the most likely first), at most `DRAWN` of
them: the plane through the primary perpendicular to the relative velocity at TCA, in the
core's axes (`core.conjunction.encounter`: x the miss direction, z = x × the relative
velocity's direction), drawn from both states and covariances the batch published:

* the combined position covariance projected onto the plane, as its 1σ and 3σ ellipses
  around the secondary (principal axes from `pc2d.eig2x2`: the Pc's own decomposition);
* the hard-body circle around the primary (the radius the Pc was computed with);
* the miss vector, primary to secondary;
* a title with the two objects, TCA, miss, relative speed and the published Pc.

Axes in m when the picture is under `KM_ABOVE_M` m across, else in km. Each element carries
a `Mark` as its ``gid`` (tests find them by it).
"""

from __future__ import annotations

import re
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ssa_fusion.apps import conjunction_table, report_figures
from ssa_fusion.core.conjunction.encounter import Encounter, encounter_plane
from ssa_fusion.core.conjunction.pc2d import eig2x2
from ssa_fusion.core.earth.timescales import iso

if TYPE_CHECKING:
    from matplotlib.axes import Axes

__all__ = ["DRAWN", "Mark", "ellipse", "file_name", "listing", "plot_approach",
           "plot_approaches"]

DRAWN = 12
"""Encounter planes drawn at most (the most likely of the table's approaches)."""
KM_ABOVE_M = 10_000.0
"""A picture this wide or wider (m) is drawn in km."""
POINTS = 361
"""Points of an ellipse's outline (its principal axes' ends are among them)."""


class Mark(StrEnum):
    """What each drawn element is (its matplotlib ``gid``)."""

    SIGMA_1 = "sigma_1"
    SIGMA_3 = "sigma_3"
    HARD_BODY = "hard_body"
    MISS = "miss"


def ellipse(cov: np.ndarray, k: float, centre: np.ndarray) -> np.ndarray:
    """Return the k-σ ellipse of a 2x2 covariance around `centre`, `POINTS` points (closed).

    Parameters
    ----------
    cov : ndarray (2, 2)
        Covariance in the plane's (x, z) axes, unit².
    k : float
        Multiple of σ.
    centre : ndarray (2,)
        Centre, unit.

    Returns
    -------
    ndarray (POINTS, 2)
        (x, z), unit; angle 0, π/2, π, 3π/2 at the ends of the principal axes.
    """
    l_major, l_minor, v = eig2x2(cov)
    major = v[0] * np.sqrt(l_major[0])
    minor = np.array([-v[0, 1], v[0, 0]]) * np.sqrt(l_minor[0])
    t = np.linspace(0.0, 2.0 * np.pi, POINTS)[:, None]
    out: np.ndarray = centre + k * (np.cos(t) * major + np.sin(t) * minor)
    return out


def file_name(rank: int, row: dict[str, Any]) -> str:
    """Return the PNG's name of the `rank`-th most likely approach (1 first)."""
    def safe(oid: str) -> str:
        return re.sub(r"[^A-Za-z0-9_-]+", "-", oid)

    return f"encounter_{rank:02d}_{safe(row['primary'])}_{safe(row['secondary'])}.png"


def _plane(row: dict[str, Any]) -> Encounter:
    """Return the approach's encounter plane (a missing covariance counts as zero), km."""
    zero = np.zeros((6, 6))
    p1 = zero if row["p1"] is None else row["p1"]
    p2 = zero if row["p2"] is None else row["p2"]
    return encounter_plane(row["x1"], p1, row["x2"], p2)


def _unit(enc: Encounter, hbr_km: float) -> tuple[float, str]:
    """Return (scale from km, unit) of the picture: m below `KM_ABOVE_M` m across."""
    sigma = float(np.sqrt(max(float(np.max(np.linalg.eigvalsh(enc.cov[0]))), 0.0)))
    across = 2.0 * (float(enc.miss_km[0]) + 3.0 * sigma + hbr_km) * 1e3
    return (1e3, "m") if across < KM_ABOVE_M else (1.0, "km")


def _draw(ax: Axes, enc: Encounter, hbr_km: float, scale: float, unit: str) -> None:
    """Draw the ellipses, the hard-body circle and the miss vector on `ax`."""
    from matplotlib.patches import Circle

    miss = enc.miss[0] * scale
    cov = enc.cov[0] * scale ** 2
    l_major, l_minor, _ = eig2x2(cov)
    if l_minor[0] > 0 and np.isfinite(l_major[0]):
        for k, mark, style in ((1.0, Mark.SIGMA_1, "-"), (3.0, Mark.SIGMA_3, "--")):
            xy = ellipse(cov, k, miss)
            ax.plot(xy[:, 0], xy[:, 1], style, color="tab:blue", lw=1.2, gid=mark.value,
                    label=f"{k:g}σ combined position covariance")
    else:
        ax.text(0.02, 0.02, "no positive-definite covariance: no ellipse",
                transform=ax.transAxes, fontsize=8)
    ax.add_patch(Circle((0.0, 0.0), hbr_km * scale, color="tab:red", alpha=0.35,
                        gid=Mark.HARD_BODY.value,
                        label=f"hard body (r = {hbr_km * scale:.3g} {unit})"))
    ax.annotate("", xy=(float(miss[0]), float(miss[1])), xytext=(0.0, 0.0),
                arrowprops={"arrowstyle": "->", "color": "k", "lw": 1.2},
                gid=Mark.MISS.value)
    ax.plot([miss[0]], [miss[1]], "o", color="k", ms=3, label="secondary at TCA (miss)")


def plot_approach(row: dict[str, Any], hbr_m: float, path: Path) -> None:
    """Draw one approach's encounter plane (module docstring) and save it as PNG.

    Parameters
    ----------
    row : dict
        One of `conjunction_table.Conjunctions.rows`.
    hbr_m : float
        The combined hard-body radius its Pc was computed with, m.
    path : Path
        Where to write the PNG.
    """
    enc = _plane(row)
    hbr_km = hbr_m / 1e3 if np.isfinite(hbr_m) else 0.0
    scale, unit = _unit(enc, hbr_km)
    fig, ax = report_figures.pyplot().subplots(figsize=(6.4, 6.0))
    _draw(ax, enc, hbr_km, scale, unit)
    ax.set_aspect("equal", adjustable="datalim")
    ax.autoscale_view()
    ax.set_xlabel(f"x: miss direction [{unit}]")
    ax.set_ylabel(f"z: x × relative velocity [{unit}]")
    ax.set_title(f"{row['primary']} – {row['secondary']}, TCA {iso(row['tca'])}\n"
                 f"Pc {conjunction_table.pc_text(row)}, miss {row['miss_m']:.1f} m, "
                 f"{row['speed_km_s']:.3f} km/s", fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="upper right")
    report_figures.save(fig, path)


def plot_approaches(c: conjunction_table.Conjunctions, out: Path,
                    shown: int = conjunction_table.SHOWN, drawn: int = DRAWN) -> list[Path]:
    """Draw the encounter planes of the `drawn` most likely of the `shown` the table lists.

    Returns the PNGs written into `out`, most likely first (`file_name`).
    """
    paths = []
    for rank, row in enumerate(c.rows[:min(shown, drawn)], start=1):
        path = out / file_name(rank, row)
        plot_approach(row, c.hbr_m, path)
        paths.append(path)
    return paths


def listing(c: conjunction_table.Conjunctions, paths: list[Path],
            shown: int = conjunction_table.SHOWN) -> str:
    """Return the report's lines naming the pictures and how many listed ones have none."""
    listed = min(shown, len(c.rows))
    left = listed - len(paths)
    head = (f"encounter planes of the {len(paths)} most likely approaches"
            + (f" ({left} of the {listed} listed left out)" if left else ""))
    return "\n".join([head + ":", *(f"  {p}" for p in paths)])
