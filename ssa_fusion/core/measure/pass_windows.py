"""Passes in a measurement stream, and the window of the last few before an epoch.

A station sees a low orbit in passes of minutes separated by hours. `passes` cuts a stream
(in epoch order) where two consecutive measurements are more than `PASS_BREAK_S` apart;
`last_passes` is the window of a fixed number of passes before an epoch, `fit_window` the
window a batch fit spans before a gap (passes within a time span, at least a number of
them, at most a number of measurements). Times in s.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ssa_fusion.core.base.types import Measurement

__all__ = ["PASS_BREAK_S", "fit_window", "last_passes", "passes", "window_start"]

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


def window_start(measurements: Sequence[Measurement], min_passes: int, span_s: float = 0.0,
                 max_measurements: int | None = None, gap_s: float = PASS_BREAK_S) -> int:
    """Return the index of the first measurement of `fit_window`'s window of `measurements`.

    `measurements` in epoch order, all of them before the window's end; see `fit_window`.
    """
    if min_passes < 1:
        raise ValueError(f"min_passes = {min_passes}: at least one pass")
    ps = passes(measurements, gap_s)
    if not ps:
        return 0
    t_last = measurements[-1].t
    k = max(0, len(ps) - min_passes)  # the first pass of the window: the last min_passes ...
    while k > 0 and t_last - measurements[ps[k - 1][0]].t <= span_s:
        k -= 1  # ... and every earlier one that starts within span_s of the last measurement
    if max_measurements is not None:
        n = len(measurements)
        while k < len(ps) - min_passes and n - ps[k][0] > max_measurements:
            k += 1  # the oldest passes go first, never one of the last min_passes
    return ps[k][0]


def fit_window(measurements: Sequence[Measurement], before: float, min_passes: int,
               span_s: float = 0.0, max_measurements: int | None = None,
               gap_s: float = PASS_BREAK_S) -> list[Measurement]:
    """Return the measurements a batch fit spans before epoch `before`.

    The passes (`passes`) of the measurements before `before` whose first measurement lies
    within `span_s` (s) of the last one, and at least the last `min_passes` passes (fewer if
    fewer exist; `span_s` 0: exactly the last `min_passes`, as `last_passes`); then, while the
    window holds more than `max_measurements` (None: no cap), its oldest pass goes, never one
    of the last `min_passes`. `measurements` in epoch order; whole passes only.
    """
    earlier = [m for m in measurements if m.t < before]
    return earlier[window_start(earlier, min_passes, span_s, max_measurements, gap_s):]
