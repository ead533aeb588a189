"""Passes in a measurement stream, and the window of the last few before an epoch.

A station sees a low orbit in passes of minutes separated by hours. `passes` cuts a stream
(in epoch order) where two consecutive measurements are more than `PASS_BREAK_S` apart;
`last_passes` is the window a batch fit spans before a gap. Times in s.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .types import Measurement

__all__ = ["PASS_BREAK_S", "last_passes", "passes"]

PASS_BREAK_S = 600.0
"""Measurements further apart than this (s) belong to different passes."""


def passes(measurements: Sequence[Measurement], gap_s: float = PASS_BREAK_S
           ) -> list[tuple[int, int]]:
    """Return the index ranges [first, last] of the passes in `measurements` (epoch order).

    A pass is a run with no two consecutive measurements more than `gap_s` apart.
    """
    if not measurements:
        return []
    t = np.array([m.t for m in measurements])
    breaks = np.flatnonzero(np.diff(t) > gap_s)
    starts = np.concatenate([[0], breaks + 1])
    ends = np.concatenate([breaks, [len(t) - 1]])
    return list(zip(starts.tolist(), ends.tolist(), strict=True))


def last_passes(measurements: Sequence[Measurement], n: int, before: float,
                gap_s: float = PASS_BREAK_S) -> list[Measurement]:
    """Return the measurements of the last `n` passes that end before epoch `before`.

    `measurements` in epoch order; the passes are cut from those before `before` only (a pass
    the epoch interrupts counts up to it). Empty if there is none; fewer passes if fewer exist.
    """
    if n < 1:
        raise ValueError(f"n = {n}: at least one pass")
    earlier = [m for m in measurements if m.t < before]
    ps = passes(earlier, gap_s)
    return earlier[ps[-n][0]:] if len(ps) >= n else earlier
