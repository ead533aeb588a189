"""The conjunctions of a catalog's bag: the approaches as the last re-screenings left them.

The conjunction node publishes each re-screening on ``/ssa/conjunctions``
(ssa_fusion_msgs/ConjunctionBatch); a batch replaces every approach of the objects it
screened. `latest` replays the batches of a bag in order and returns what stands at its
end; `table` prints the most likely of them (by Pc, then miss) as markdown, and
`write_csv` writes every one.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ssa_fusion.core.earth.timescales import iso
from ssa_fusion.ros import bagio, messages
from ssa_fusion.ros.topics import TOPIC_CONJUNCTIONS

COLUMNS = ("primary", "secondary", "TCA (UTC)", "miss [m]", "R [m]", "T [m]", "N [m]",
           "speed [km/s]", "Pc")
"""The columns of the table."""
SHOWN = 20
"""Rows of the printed table (the most likely approaches)."""


@dataclass(frozen=True)
class Conjunctions:
    """The approaches standing at the end of a bag, and what published them.

    Attributes
    ----------
    rows : list of dict
        One per approach: ``primary``, ``secondary``, ``tca`` (Unix s), ``miss_m``,
        ``rtn_m`` (radial, along-track, cross-track of the secondary from the primary),
        ``speed_km_s``, ``pc``, ``log10_pc``.
    batches : int
        ConjunctionBatch messages read.
    screened : int
        Objects re-screened over all batches.
    distance_m, hbr_m : float
        The last batch's screening distance and hard-body radius, m (NaN without one).
    """

    rows: list[dict[str, Any]]
    batches: int
    screened: int
    distance_m: float
    hbr_m: float


def latest(bag: Path) -> Conjunctions:
    """Return the approaches that stand at the end of `bag` (module docstring)."""
    standing: dict[tuple[str, str, float], dict[str, Any]] = {}
    batches = screened = 0
    distance = hbr = float("nan")
    for m in bagio.read_bag(bag, topics=[TOPIC_CONJUNCTIONS]):
        up = messages.conjunction_batch_from_msg(m.msg)
        batches += 1
        screened += len(up.screened)
        distance, hbr = up.distance_km * 1e3, up.hbr_km * 1e3
        gone = set(up.screened)
        standing = {k: v for k, v in standing.items() if not {k[0], k[1]} & gone}
        a = up.approaches
        rtn = a.relative_rtn()
        for k in range(len(a)):
            p, s = a.object_ids[int(a.primary[k])], a.object_ids[int(a.secondary[k])]
            lg = float(up.log10_pc[k])
            standing[(p, s, float(a.tca[k]))] = {
                "primary": p, "secondary": s, "tca": float(a.tca[k]),
                "miss_m": float(a.miss_km[k]) * 1e3,
                "rtn_m": [float(v) * 1e3 for v in rtn[k, :3]],
                "speed_km_s": float(np.linalg.norm(rtn[k, 3:])),
                "pc": 10.0 ** lg if lg > -300 else 0.0, "log10_pc": lg}
    rows = sorted(standing.values(), key=lambda r: (-r["log10_pc"], r["miss_m"]))
    return Conjunctions(rows, batches, screened, distance, hbr)


def _pc(r: dict[str, Any]) -> str:
    return f"{r['pc']:.3g}" if r["pc"] > 0 else f"1e{r['log10_pc']:.1f}"


def cells(c: Conjunctions, shown: int = SHOWN) -> list[list[str]]:
    """Return the table's cells: the `shown` most likely approaches."""
    return [[r["primary"], r["secondary"], iso(r["tca"]), f"{r['miss_m']:.1f}",
             *(f"{v:.1f}" for v in r["rtn_m"]), f"{r['speed_km_s']:.3f}", _pc(r)]
            for r in c.rows[:shown]]


def table(c: Conjunctions, shown: int = SHOWN) -> str:
    """Markdown: a line of counts, then the `shown` most likely approaches."""
    head = (f"conjunctions: {len(c.rows)} approaches standing (within {c.distance_m:g} m, "
            f"Pc with a {c.hbr_m:g} m hard-body radius) after {c.batches} re-screenings of "
            f"{c.screened} objects in all")
    if not c.rows:
        return head
    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS),
             *("| " + " | ".join(row) + " |" for row in cells(c, shown))]
    return head + f"; the {min(shown, len(c.rows))} most likely:\n" + "\n".join(lines)


def write_csv(c: Conjunctions, path: Path) -> None:
    """Write every standing approach to `path` (CSV, one line each, most likely first)."""
    import csv

    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["primary", "secondary", "tca_utc", "miss_m", "radial_m", "along_m",
                    "cross_m", "speed_km_s", "pc", "log10_pc"])
        for r in c.rows:
            w.writerow([r["primary"], r["secondary"], iso(r["tca"]), f"{r['miss_m']:.3f}",
                        *(f"{v:.3f}" for v in r["rtn_m"]), f"{r['speed_km_s']:.6f}",
                        f"{r['pc']:.6g}", f"{r['log10_pc']:.4f}"])
