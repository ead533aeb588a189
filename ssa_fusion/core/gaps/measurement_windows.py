"""The real measurements of each object's last passes, as arrays: `MeasurementWindows`.

What a catalog's batch fit of the gaps (`gap_bank.GapBank` with `gap_publisher.GapFill.
BATCH_FIT`) spans per object: the window of the last ``passes`` passes, as
`gap_bank.last_passes_forecaster`'s `batch_gap.BatchGapForecaster` keeps it for one object
(a measurement at or before the window's newest epoch is ignored; one
more than ``pass_break_s`` after it starts a pass; the oldest pass is forgotten when a pass
beyond ``passes`` starts), here for many objects at once. A catalog holds tens of thousands
of objects, so an object's window is one structured array (`ROW`, 40 bytes a measurement:
epoch, z, kind, station, noise) rather than a list of `Measurement`s; the noise covariances
of a catalog's measurements are its radars' few, stored once each (`noise`). At most
``max_rows`` measurements per object are kept (the oldest forgotten beyond them, within the
oldest pass): a bound on memory whatever the sensors' cadence.

`window` rebuilds an object's window as the `Measurement`s a fit takes.
Units: epochs s (the measurements' clock), z and R in the measurements' units.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.types import Kind, Measurement, Source
from ssa_fusion.core.gaps.batch_gap import GAP_FIT_PASSES
from ssa_fusion.core.measure.pass_windows import PASS_BREAK_S

__all__ = ["MAX_WINDOW_ROWS", "ROW", "MeasurementWindows"]

ROW = np.dtype([("t", "f8"), ("z", "f8", (3,)), ("kind", "u1"), ("station", "u2"),
                ("noise", "u4")], align=False)
"""One measurement of a window: epoch s, z (3,) (RA_DEC: third 0), `Kind`, station index
(`MeasurementWindows.stations`), noise index (`MeasurementWindows.noise`)."""

MAX_WINDOW_ROWS = 512
"""Most measurements an object's window keeps: three passes of a radar network (a radar
sees a LEO object for minutes at a 10 s cadence: tens of measurements a pass and station)
fit well inside it."""

_FIRST_ROWS = 16


class MeasurementWindows:
    """The measurements of the last `passes` passes of each object (module docstring).

    Objects are rows 0, 1, ... (the caller's numbering, e.g. a `GapBank`'s); `grow` makes
    room for them.

    Parameters
    ----------
    passes : int
        Passes a window spans.
    pass_break_s : float
        A measurement more than this (s) after the window's newest starts a pass.
    max_rows : int
        Most measurements kept per object.
    """

    def __init__(self, passes: int = GAP_FIT_PASSES, pass_break_s: float = PASS_BREAK_S,
                 max_rows: int = MAX_WINDOW_ROWS) -> None:
        if passes < 1 or max_rows < 1:
            raise ValueError(f"passes and max_rows must be >= 1, got {passes}, {max_rows}")
        self.passes = int(passes)
        self.pass_break_s = float(pass_break_s)
        self.max_rows = int(max_rows)
        self.stations: list[str] = []
        """Station ids (``frame_id``) by index."""
        self.noise: list[NDArray[np.float64]] = []
        """The distinct noise covariances (3, 3) by index."""
        self._station_index: dict[str, int] = {}
        self._noise_index: dict[bytes, int] = {}
        self._rows: list[NDArray[np.void] | None] = []  # per object, capacity >= its count
        self._count = np.zeros(0, np.int32)  # measurements kept per object
        self._starts = np.zeros((0, self.passes), np.int32)  # first row of each pass kept
        self._npass = np.zeros(0, np.int16)  # passes kept per object

    def grow(self, n: int) -> None:
        """Make room for objects 0 .. n-1."""
        k = n - len(self._rows)
        if k > 0:
            self._rows.extend([None] * k)
            self._count = np.r_[self._count, np.zeros(k, np.int32)]
            self._starts = np.concatenate([self._starts, np.zeros((k, self.passes), np.int32)])
            self._npass = np.r_[self._npass, np.zeros(k, np.int16)]

    def __len__(self) -> int:
        """Return the number of objects with room."""
        return len(self._rows)

    def count(self, r: int) -> int:
        """Return the number of measurements object `r`'s window holds."""
        return int(self._count[r])

    def pass_count(self, r: int) -> int:
        """Return the number of passes object `r`'s window spans."""
        return int(self._npass[r])

    def nbytes(self) -> int:
        """Return the bytes of the windows' arrays (their allocated capacity)."""
        return sum(a.nbytes for a in self._rows if a is not None) + int(
            self._count.nbytes + self._starts.nbytes + self._npass.nbytes)

    @staticmethod
    def _index(table: dict[Any, int], values: list[Any], key: object, value: object) -> int:
        """Return the index of `key` in `table`, adding `value` to `values` if new."""
        i = table.get(key)
        if i is None:
            i = table[key] = len(values)
            values.append(value)
        return int(i)

    def add(self, r: int, t: float, z: ArrayLike, R: ArrayLike, kind: int,
            frame_id: str) -> bool:
        """Add a real measurement of object `r` (epoch order); return whether it was kept.

        z (2,) or (3,) and R in the units of `kind` (`types.Measurement`).
        """
        n = int(self._count[r])
        rows = self._rows[r]
        if n and not t > rows[n - 1]["t"]:  # type: ignore[index]
            return False
        if not n or t - rows[n - 1]["t"] > self.pass_break_s:  # type: ignore[index]
            if self._npass[r] == self.passes:  # forget the oldest pass
                self._drop(r, int(self._starts[r, 1]) if self.passes > 1 else n)
            n = int(self._count[r])
            self._starts[r, self._npass[r]] = n
            self._npass[r] += 1
        if n == self.max_rows:  # the window is full: forget its oldest measurement
            self._drop(r, 1)
            n -= 1
        rows = self._rows[r]
        if rows is None or rows.size == n:
            bigger = np.zeros(min(max(2 * n, _FIRST_ROWS), self.max_rows), ROW)
            if rows is not None:
                bigger[:n] = rows[:n]
            rows = self._rows[r] = bigger
        zz = np.zeros(3)
        z = np.asarray(z, float).ravel()
        zz[:z.size] = z
        R = np.asarray(R, float)
        rows[n] = (t, zz, int(kind),
                   self._index(self._station_index, self.stations, frame_id, frame_id),
                   self._index(self._noise_index, self.noise, R.tobytes() + bytes(R.shape),
                               R.copy()))
        self._count[r] = n + 1
        return True

    def forget(self, r: int) -> None:
        """Forget object `r`'s window (its memory too)."""
        self._rows[r] = None
        self._count[r] = 0
        self._starts[r] = 0
        self._npass[r] = 0

    def _drop(self, r: int, k: int) -> None:
        """Forget the oldest `k` measurements of object `r` (the pass starts move with them)."""
        rows, n = self._rows[r], int(self._count[r])
        assert rows is not None
        rows[:n - k] = rows[k:n]
        self._count[r] = n - k
        p = int(self._npass[r]) if n > k else 0
        starts = np.maximum(self._starts[r, :p] - k, 0)
        keep = np.r_[True, starts[1:] > 0][:p]  # a pass all of whose rows went is gone
        starts = starts[keep]
        self._starts[r, :] = 0
        self._starts[r, :starts.size] = starts
        self._npass[r] = starts.size

    def window(self, r: int) -> list[Measurement]:
        """Return object `r`'s window as Measurements (SENSOR, epoch order)."""
        rows = self._rows[r]
        out = []
        for row in ([] if rows is None else rows[:int(self._count[r])]):
            R = self.noise[int(row["noise"])]
            out.append(Measurement(t=float(row["t"]), z=row["z"][:R.shape[0]].copy(), R=R,
                                   kind=Kind(int(row["kind"])), source=Source.SENSOR,
                                   frame_id=self.stations[int(row["station"])]))
        return out

    def last_t(self, r: int) -> float:
        """Return the epoch (s) of object `r`'s newest measurement (-inf: none)."""
        n = int(self._count[r])
        rows = self._rows[r]
        return -math.inf if not n or rows is None else float(rows[n - 1]["t"])
