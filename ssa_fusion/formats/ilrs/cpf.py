"""Reading a CPF file (ILRS Consolidated Prediction Format, v1 and v2): an orbit in the ITRF.

A CPF is what a laser station points with: the target's centre-of-mass positions (record
10: MJD, seconds of day, leap-second flag, x y z in m) every few minutes, optionally its
velocities (record 20, m/s), in a geocentric frame named by H2 (0: true body-fixed, the
ITRF, the only one taken here). `read_cpf` reads the file line by line
(`records.RecordLines`) into a `CpfOrbit`: the header's ids and the epochs (Unix s, UTC),
positions and velocities in km and km/s (the core's units). An orbit for evaluation, or a
start for orbit determination: `core.motion.tabulated` interpolates it.

Checked: H1 first (``CPF``, version 1 or 2), H2 (ids, start and end, step, the frame, the
centre-of-mass flag), H3 .. H5 in order and H9 before the data, comments (``00``) anywhere;
then records 10 (direction flag 0, the common epoch: the light-time-corrected transmit (1)
and receive (2) vectors of lunar CPFs are refused), each at most one record 20 of its
epoch, 30 .. 70 (checked, not used), and 99 last: a file that ends before it is
truncated. Epochs strictly increase and lie within the header's start .. end (plus one
step); positions are 6350 km to 1e9 km from the geocentre (a target below the ground is
an error); every field is a finite decimal number in its range (`records.Fields`).
Velocities are given for every epoch or for none.
"""

from __future__ import annotations

import calendar
import datetime as dt
from array import array
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ssa_fusion.core.base.quoting import shown
from ssa_fusion.core.earth.timescales import EPOCH_MAX, EPOCH_MIN, iso
from ssa_fusion.formats.records import Fields, RecordLines

Array = NDArray[np.float64]

MJD_UNIX = 40587
"""The MJD of 1970-01-01."""
MIN_RADIUS_M, MAX_RADIUS_M = 6.35e6, 1e12
"""Distances from the geocentre taken, m (the Earth's surface .. beyond the Moon)."""
MAX_POINTS = 2_000_000
"""Most positions read (a week at 1 s): more is not a prediction file."""
_LATER = ("30", "40", "50", "60", "70")
"""Records after a position checked but not used."""


@dataclass(frozen=True)
class CpfOrbit:
    """A CPF's orbit (module docstring).

    Attributes
    ----------
    target, ilrs_id, norad, source
        The target's name (H1), ILRS id and NORAD id (H2; None when not given), the
        ephemeris source (H1, e.g. "SGF").
    start, end, step_s
        The header's span (Unix s, UTC) and the time between entries (s).
    com_applied
        H2: True when the positions are of the retro-reflector array (the centre-of-mass
        correction applied), False (the usual) for the centre of mass.
    t
        Epochs (n,), Unix s (UTC), increasing.
    position_km, velocity_km_s
        ITRF positions (n, 3), km, and velocities (n, 3), km/s, or None.
    """

    target: str
    ilrs_id: int
    norad: int | None
    source: str
    start: float
    end: float
    step_s: float
    com_applied: bool
    t: Array
    position_km: Array
    velocity_km_s: Array | None


def _date(f: Fields, i: int, name: str) -> tuple[int, int, int]:
    """Return (year, month, day) of fields `i` .. `i + 2`, a date that exists."""
    y = f.integer(i, f"{name} year", 1950, 2100)
    mo = f.integer(i + 1, f"{name} month", 1, 12)
    d = f.integer(i + 2, f"{name} day", 1, 31)
    try:
        dt.date(y, mo, d)
    except ValueError:
        f.fail(f"{name}: {y:04d}-{mo:02d}-{d:02d} is not a date")
    return y, mo, d


def _epoch(f: Fields, i: int, name: str) -> float:
    """Return the Unix epoch of fields `i` .. `i + 5` (year month day hour minute second)."""
    y, mo, d = _date(f, i, name)
    h = f.integer(i + 3, f"{name} hour", 0, 23)
    mi = f.integer(i + 4, f"{name} minute", 0, 59)
    s = f.integer(i + 5, f"{name} second", 0, 60)
    t = float(calendar.timegm((y, mo, d, h, mi, s)))
    if not EPOCH_MIN <= t <= EPOCH_MAX:
        f.fail(f"{name} {iso(t)}: outside {iso(EPOCH_MIN)} .. {iso(EPOCH_MAX)}")
    return t


class _Reading:
    """The state of `read_cpf`: headers read, positions and velocities so far."""

    def __init__(self, lines: RecordLines) -> None:
        self.lines = lines
        self.version = 0
        self.headers: list[str] = []
        self.h1: dict[str, str] = {}
        self.h2: dict[str, float] = {}
        self.t = array("d")
        self.xyz = array("d")
        self.vel = array("d")
        self.vel_t = array("d")
        self.done = False

    def header(self, record: str, f: Fields) -> None:
        """Read H1 .. H5 or H9 (in order)."""
        order = ("H1", "H2", "H3", "H4", "H5", "H9")
        if self.headers and order.index(record) <= order.index(self.headers[-1]):
            f.fail(f"after {self.headers[-1]}: the headers come in the order "
                   f"{', '.join(order)}")
        if record != "H1" and "H1" not in self.headers:
            f.fail("before H1")
        if record == "H9" and "H2" not in self.headers:
            f.fail("before H2: the header needs H1 and H2")
        self.headers.append(record)
        if record == "H1":
            self._h1(f)
        elif record == "H2":
            self._h2(f)
        elif record == "H9":
            f.count(0, 0)
        else:  # H3 .. H5: checked, not used (along-track runoff, transponder, offset)
            f.count(1, 6)
            for i in range(1, len(f.tokens)):
                f.number(i, f"field {i}", -1e15, 1e15)

    def _h1(self, f: Fields) -> None:
        f.count(9, 10)
        if f.word(1, "format").upper() != "CPF":
            f.fail(f"format {shown(f.tokens[1])}: not a CPF file (want CPF)")
        self.version = f.integer(2, "version", 1, 2)
        f.count(9 + (self.version == 2), 9 + (self.version == 2))
        source = f.word(3, "ephemeris source", 10)
        _date(f, 4, "production date")
        f.integer(7, "production hour", 0, 23)
        f.integer(8, "ephemeris sequence number", 0, 99999)
        if self.version == 2:
            f.integer(9, "sub-daily sequence number", 0, 99)
        self.h1 = {"source": source, "target": f.word(len(f.tokens) - 1, "target name", 10)}

    def _h2(self, f: Fields) -> None:
        n = 21 + (self.version == 2)
        f.count(n, n)
        self.h2["ilrs_id"] = f.integer(1, "ILRS id", 0, 99999999)
        f.integer(2, "SIC", -1, 9999)
        norad = f.integer(3, "NORAD id", -1, 999999999)
        self.h2["norad"] = -1 if norad <= 0 else norad
        self.h2["start"] = _epoch(f, 4, "start")
        self.h2["end"] = _epoch(f, 10, "end")
        if self.h2["end"] <= self.h2["start"]:
            f.fail(f"end {iso(self.h2['end'])} not after start {iso(self.h2['start'])}")
        self.h2["step"] = f.integer(16, "time between entries", 1, 86400)
        f.integer(17, "compatibility with TIVs", 0, 1)
        f.integer(18, "target type", 0, 9)
        frame = f.integer(19, "reference frame", 0, 2)
        if frame != 0:
            f.fail(f"reference frame {frame} (1: true of date, 2: mean of J2000): this "
                   f"reader takes 0, the geocentric body-fixed frame (ITRF)")
        f.integer(20, "rotational angle type", 0, 2)
        self.h2["com"] = f.integer(21, "centre-of-mass correction", 0, 1)
        if self.version == 2:
            f.integer(22, "target location", 0, 9)

    def position(self, f: Fields) -> None:
        """Read record 10 (a position)."""
        f.count(7, 7)
        direction = f.integer(1, "direction flag", 0, 2)
        if direction != 0:
            f.fail(f"direction flag {direction} (light-time-corrected vectors): this reader "
                   f"takes 0, the common epoch")
        t = self._mjd_epoch(f, 2)
        xyz = [f.number(i, "xyz"[i - 5], -MAX_RADIUS_M, MAX_RADIUS_M, "m") for i in (5, 6, 7)]
        r = float(np.linalg.norm(xyz))
        if r < MIN_RADIUS_M:
            f.fail(f"position {r / 1000.0:.3f} km from the geocentre: below the Earth's "
                   f"surface")
        if self.t and t <= self.t[-1]:
            f.fail(f"epoch {iso(t)} not after the one before ({iso(self.t[-1])})")
        if len(self.t) >= MAX_POINTS:
            f.fail(f"more than {MAX_POINTS} positions: not a prediction file")
        self.t.append(t)
        self.xyz.extend(xyz)

    def _mjd_epoch(self, f: Fields, i: int) -> float:
        mjd = f.integer(i, "MJD", 41317, 65000)
        sod = f.number(i + 1, "seconds of day", 0.0, 86401.0 - 1e-9, "s")
        f.integer(i + 2, "leap second flag", -1, 60)
        t = (mjd - MJD_UNIX) * 86400.0 + sod
        lo, hi = self.h2["start"], self.h2["end"] + self.h2["step"]
        if not lo - 1.0 <= t <= hi:
            f.fail(f"epoch {iso(t)} outside the header's {iso(lo)} .. {iso(hi)}")
        return t

    def velocity(self, f: Fields) -> None:
        """Read record 20 (the velocity at the last position's epoch)."""
        f.count(4, 4)
        if not self.t:
            f.fail("a velocity before any position")
        if self.vel_t and self.vel_t[-1] == self.t[-1]:
            f.fail("a second velocity for one position")
        f.integer(1, "direction flag", 0, 2)
        self.vel.extend(f.number(i, f"v{'xyz'[i - 2]}", -1e6, 1e6, "m/s") for i in (2, 3, 4))
        self.vel_t.append(self.t[-1])

    def later(self, f: Fields) -> None:
        """Check a record 30 .. 70 (corrections, transponder, offsets, rotation, EOP)."""
        if not self.t:
            f.fail("before any position (record 10)")
        f.count(1, 12)
        for i in range(1, len(f.tokens)):
            f.number(i, f"field {i}", -1e15, 1e15)


def read_cpf(path: Path | str) -> CpfOrbit:
    """Return the orbit of a CPF file (module docstring).

    `records.RecordError`, one line naming the file, the line, the record and the field,
    for anything that is not a CPF's or not supported.
    """
    lines = RecordLines(path, "a CPF file")
    state = _Reading(lines)
    n = 0
    for n, text in lines:
        record = text.split(maxsplit=1)[0].upper()
        f = Fields(lines, n, text, record if record[0].isalpha() else f"record {record}")
        if record == "00":
            continue
        if state.done:
            f.fail("after record 99 (the end of the ephemeris)")
        if not state.headers and record != "H1":
            f.fail("not a CPF file (a CPF file starts with H1)")
        if record in ("H1", "H2", "H3", "H4", "H5", "H9"):
            if state.t:
                f.fail("a header record after the positions")
            state.header(record, f)
            continue
        if "H9" not in state.headers:
            f.fail("before H9 (the end of the header)")
        if record == "10":
            state.position(f)
        elif record == "20":
            state.velocity(f)
        elif record in _LATER:
            state.later(f)
        elif record == "99":
            f.count(0, 0)
            state.done = True
        else:
            f.fail("not a CPF record")
    return _orbit(lines, state, n)


def _orbit(lines: RecordLines, state: _Reading, n: int) -> CpfOrbit:
    """Return the orbit read (the end of the file checked)."""
    if n == 0:
        lines.fail(1, "empty: not a CPF file")
    if not state.done:
        lines.fail(n, "the file ends without record 99 (the end of the ephemeris): "
                      "truncated?")
    if len(state.t) < 2:
        lines.fail(n, f"{len(state.t)} position(s): an orbit needs at least two")
    t = np.frombuffer(state.t, dtype=float).copy()
    vel = None
    if state.vel_t:
        if len(state.vel_t) != len(state.t):
            lines.fail(n, f"velocities for {len(state.vel_t)} of the {len(state.t)} "
                          f"positions: give them for every epoch or for none")
        vel = np.frombuffer(state.vel, dtype=float).reshape(-1, 3) / 1000.0
    h2 = state.h2
    return CpfOrbit(target=state.h1["target"], ilrs_id=int(h2["ilrs_id"]),
                    norad=None if h2["norad"] < 0 else int(h2["norad"]),
                    source=state.h1["source"], start=h2["start"], end=h2["end"],
                    step_s=h2["step"], com_applied=h2["com"] == 1, t=t,
                    position_km=np.frombuffer(state.xyz, dtype=float).reshape(-1, 3) / 1000.0,
                    velocity_km_s=vel)
