"""Reading station coordinates from SINEX: positions, velocities and eccentricities.

SINEX (Solution INdependent EXchange format, version 2.x, IERS) is how the reference frames
(ITRF, and the ILRS's SLRF) and the stations' eccentricities are published. Two readers,
each streaming the file line by line (`records.RecordLines`) and reading only its blocks:

* `read_solutions`: ``SOLUTION/ESTIMATE`` parameters STAX, STAY, STAZ (m) and VELX, VELY,
  VELZ (m/y) of each station (site code, point code, solution number) with their reference
  epoch, and the ``SOLUTION/EPOCHS`` each solution holds for (a station whose equipment
  changed has several solutions, each for its own span) -> `StationSolution`;
* `read_eccentricities`: ``SITE/ECCENTRICITY`` (marker -> reference point, Up North East
  in m, ``UNE``; ``XYZ`` is refused) with the span each holds for -> `Eccentricity`.

`solution_at` and `eccentricity_at` choose a station's entry for an epoch. Checked: the
header line (``%=SNX``) first, blocks that open (``+NAME``) and close (``-NAME``) in pairs,
``%ENDSNX`` last (a file without it is truncated), and every field of the lines read: codes
of their width, integers, decimal numbers within range (a position 6350 .. 6400 km from the
geocentre, a velocity under 1 m/y, an eccentricity under 10 km), units (m, m/y), epochs
``YY:DDD:SSSSS`` that exist (``00:000:00000`` is "open": no bound), a parameter given
twice. Errors are one line naming the file, the line and the field (`records.RecordError`).
Epochs are Unix s (UTC); values in the file's m and m/y.
"""

from __future__ import annotations

import calendar
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ssa_fusion.core.base.quoting import shown
from ssa_fusion.core.earth.timescales import iso
from ssa_fusion.formats.records import Fields, RecordError, RecordLines

Array = NDArray[np.float64]

_EPOCH = re.compile(r"(\d{2}):(\d{3}):(\d{5})")
_COLUMNS = {
    "SOLUTION/ESTIMATE": ((1, 6), (7, 13), (14, 18), (19, 21), (22, 26), (27, 39), (40, 44),
                          (45, 46), (46, 68), (68, 80)),
    "SOLUTION/EPOCHS": ((1, 5), (6, 8), (9, 13), (14, 15), (16, 28), (29, 41), (42, 54)),
    "SITE/ECCENTRICITY": ((1, 5), (6, 8), (9, 13), (14, 15), (16, 28), (29, 41), (42, 45),
                          (45, 54), (54, 63), (63, 72)),
}
"""The columns (0-based, [start, end)) of the fields of each block read (SINEX 2.02:
fixed format; a number may fill the blank before it, as eccentricities of over 100 m do)."""
_PARAMETERS = ("STAX", "STAY", "STAZ", "VELX", "VELY", "VELZ")
_UNITS = {"STA": "m", "VEL": "m/y"}
MAX_SITE_RADIUS_M = (6.35e6, 6.40e6)
"""Distances of a station from the geocentre taken, m."""
MAX_VELOCITY_M_YR = 1.0
"""Largest station velocity component taken, m/yr (plates move a few cm a year)."""
MAX_ECCENTRICITY_M = 10_000.0
"""Largest eccentricity component taken, m (a mobile system parked km from its marker)."""

Key = tuple[str, str, str]
"""A station solution's (site code, point code, solution number), as the file writes them."""


@dataclass(frozen=True)
class StationSolution:
    """A station's coordinates in one solution (module docstring).

    `position_m` (ITRF, m) at `t_ref` (Unix s), `velocity_m_yr` (m/yr; zero when the file
    gives none), `sigma_m` the positions' standard deviations; `start` .. `end` the span
    the solution holds for (None: unbounded); `line` where its STAX is.
    """

    code: str
    point: str
    solution: str
    position_m: Array
    velocity_m_yr: Array
    sigma_m: Array
    t_ref: float
    start: float | None
    end: float | None
    line: int


@dataclass(frozen=True)
class Eccentricity:
    """A station's eccentricity (Up, North, East m) over a span (None: unbounded)."""

    code: str
    point: str
    solution: str
    une_m: Array
    start: float | None
    end: float | None
    line: int


def _epoch(f: Fields, i: int, name: str) -> float | None:
    """Return field `i` (``YY:DDD:SSSSS``) as a Unix epoch; None for ``00:000:00000``."""
    tok = f.raw(i, name)
    m = _EPOCH.fullmatch(tok)
    if not m:
        f.fail(f"{name}: {shown(tok)} is not an epoch YY:DDD:SSSSS")
    yy, doy, sod = (int(g) for g in m.groups())
    if yy == 0 and doy == 0 and sod == 0:
        return None
    year = 2000 + yy if yy <= 50 else 1900 + yy
    days = 366 if calendar.isleap(year) else 365
    if not 0 <= doy <= days or sod > 86400:
        f.fail(f"{name}: {tok} is not a day of {year} (day 1..{days}, 0..86400 s)")
    return float(calendar.timegm((year, 1, 1, 0, 0, 0))) + (doy - 1) * 86400.0 + sod


def _blocks(lines: RecordLines, wanted: tuple[str, ...]) -> Iterator[tuple[str, Fields]]:
    """Yield (block, fields) of the data lines of the `wanted` blocks (structure checked)."""
    block = ""
    block_line = 0
    n = 0
    header = ended = False
    for n, text in lines:
        if not header:
            if not text.startswith("%=SNX"):
                lines.fail(n, f"not a SINEX file (its first line starts "
                              f"{shown(text[:20])}, not %=SNX)")
            header = True
            continue
        if ended:
            lines.fail(n, "after %ENDSNX (the end of the file)")
        head = text[:1]
        if head == "*":
            continue
        if text.startswith("%ENDSNX"):
            if block:
                lines.fail(n, f"%ENDSNX inside block {block} (opened at line {block_line})")
            ended = True
            continue
        if head in "+-":
            name = text[1:].strip()
            block, block_line = _block_mark(lines, n, head, name, block, block_line)
            continue
        if not block:
            lines.fail(n, f"a data line outside any block: {shown(text[:40])}")
        if head != " ":
            lines.fail(n, f"{block}: a data line must start with a blank: {shown(text[:40])}")
        if block in wanted:
            yield block, Fields.columns(lines, n, text, block, _COLUMNS[block])
    if n == 0:
        lines.fail(1, "empty: not a SINEX file")
    if block:
        lines.fail(n, f"the file ends inside block {block} (opened at line {block_line}): "
                      f"truncated?")
    if not ended:
        lines.fail(n, "the file ends without %ENDSNX: truncated?")


def _block_mark(lines: RecordLines, n: int, head: str, name: str, block: str,
                block_line: int) -> tuple[str, int]:
    """Return the block open after a ``+NAME`` or ``-NAME`` line (pairs checked)."""
    if not name or len(name) > 40 or not name.isprintable():
        lines.fail(n, f"block name {shown(name)}: not a SINEX block")
    if head == "+":
        if block:
            lines.fail(n, f"+{name} inside block {block} (opened at line {block_line})")
        return name, n
    if name != block:
        lines.fail(n, f"-{name} closes no open block" + (f" ({block} is open since line "
                                                         f"{block_line})" if block else ""))
    return "", 0


def _key(f: Fields) -> Key:
    """Return the (site code, point code, solution) of fields 1 .. 3 of a site line."""
    return (f.word(1, "site code", 4), f.word(2, "point code", 2), f.word(3, "solution", 4))


def read_solutions(path: Path | str) -> dict[Key, StationSolution]:
    """Return the station solutions of a SINEX file by (site code, point code, solution).

    Module docstring; RecordError (one line) for a file that is not one or a bad field.
    """
    lines = RecordLines(path, "a SINEX file")
    values: dict[Key, dict[str, tuple[float, float, float, int]]] = {}
    spans: dict[Key, tuple[float | None, float | None]] = {}
    for block, f in _blocks(lines, ("SOLUTION/ESTIMATE", "SOLUTION/EPOCHS")):
        if block == "SOLUTION/EPOCHS":
            key = _key(f)
            f.word(4, "observation code", 1)
            spans[key] = (_epoch(f, 5, "data start"), _epoch(f, 6, "data end"))
            _epoch(f, 7, "mean epoch")
            continue
        f.integer(1, "index", 0, 99999)
        kind = f.word(2, "parameter type", 6)
        if kind not in _PARAMETERS:
            continue  # other parameters (EOP, ...) are not stations'
        key = (f.word(3, "site code", 4), f.word(4, "point code", 2), f.word(5, "solution", 4))
        t_ref = _epoch(f, 6, "reference epoch")
        if t_ref is None:
            f.fail("reference epoch 00:000:00000: a parameter needs its epoch")
        unit = f.word(7, "unit", 4)
        if unit != _UNITS[kind[:3]]:
            f.fail(f"unit {shown(unit)} of {kind}: want {_UNITS[kind[:3]]}")
        f.integer(8, "constraint code", 0, 2)
        lim = MAX_SITE_RADIUS_M[1] if kind[:3] == "STA" else MAX_VELOCITY_M_YR
        value = f.number(9, "estimated value", -lim, lim, unit)
        sigma = f.number(10, "standard deviation", 0.0, 1e6, unit)
        got = values.setdefault(key, {})
        if kind in got:
            f.fail(f"{kind} of {' '.join(key)} given twice (first at line {got[kind][3]})")
        got[kind] = (value, sigma, t_ref, f.line)
    return {key: _solution(lines, key, got, spans.get(key, (None, None)))
            for key, got in values.items()}


def _solution(lines: RecordLines, key: Key, got: dict[str, tuple[float, float, float, int]],
              span: tuple[float | None, float | None]) -> StationSolution:
    """Return one station's solution from its parameters (all three STA needed)."""
    where = min(v[3] for v in got.values())
    missing = [p for p in _PARAMETERS[:3] if p not in got]
    if missing:
        lines.fail(where, f"SOLUTION/ESTIMATE: station {' '.join(key)} has no "
                          f"{', '.join(missing)}")
    epochs = {v[2] for v in got.values()}
    if len(epochs) > 1:
        lines.fail(where, f"SOLUTION/ESTIMATE: station {' '.join(key)}: its parameters have "
                          f"different reference epochs")
    pos = np.array([got[p][0] for p in _PARAMETERS[:3]])
    r = float(np.linalg.norm(pos))
    if not MAX_SITE_RADIUS_M[0] <= r <= MAX_SITE_RADIUS_M[1]:
        lines.fail(got["STAX"][3], f"SOLUTION/ESTIMATE: station {' '.join(key)} is "
                                   f"{r / 1000.0:.3f} km from the geocentre: not at the "
                                   f"Earth's surface")
    vel = np.array([got[p][0] if p in got else 0.0 for p in _PARAMETERS[3:]])
    return StationSolution(*key, position_m=pos, velocity_m_yr=vel,
                           sigma_m=np.array([got[p][1] for p in _PARAMETERS[:3]]),
                           t_ref=epochs.pop(), start=span[0], end=span[1],
                           line=got["STAX"][3])


def read_eccentricities(path: Path | str) -> list[Eccentricity]:
    """Return the ``SITE/ECCENTRICITY`` entries of a SINEX file, in file order.

    Module docstring; RecordError (one line) for a file that is not one or a bad field.
    """
    lines = RecordLines(path, "a SINEX file")
    out = []
    for _, f in _blocks(lines, ("SITE/ECCENTRICITY",)):
        key = _key(f)
        f.word(4, "observation code", 1)
        start, end = _epoch(f, 5, "data start"), _epoch(f, 6, "data end")
        if start is not None and end is not None and end < start:
            f.fail(f"data end {iso(end)} before data start {iso(start)}")
        system = f.word(7, "reference system", 3)
        if system != "UNE":
            f.fail(f"reference system {shown(system)}: this reader takes UNE (up, north, "
                   f"east)")
        une = [f.number(i, name, -MAX_ECCENTRICITY_M, MAX_ECCENTRICITY_M, "m")
               for i, name in ((8, "up"), (9, "north"), (10, "east"))]
        out.append(Eccentricity(*key, une_m=np.array(une), start=start, end=end,
                                line=f.line))
    return out


def _covers(start: float | None, end: float | None, t: float) -> bool:
    return (start is None or start <= t) and (end is None or t <= end)


def solution_at(solutions: dict[Key, StationSolution], code: str, t: float,
                path: str = "") -> StationSolution:
    """Return station `code`'s solution whose span holds epoch `t` (Unix s).

    RecordError naming the file (`path`) when there is none, or several.
    """
    mine = [s for k, s in solutions.items() if k[0] == code]
    hit = [s for s in mine if _covers(s.start, s.end, t)]
    if len(hit) == 1:
        return hit[0]
    if not mine:
        raise RecordError(f"{path}: no SOLUTION/ESTIMATE of station {shown(code)}")
    what = "no solution" if not hit else f"{len(hit)} solutions"
    raise RecordError(f"{path}: station {shown(code)}: {what} for {iso(t)} (its solutions: "
                      + ", ".join(f"{s.solution} {_span(s.start, s.end)}" for s in mine)
                      + ")")


def eccentricity_at(eccentricities: list[Eccentricity], code: str, t: float,
                    path: str = "") -> Eccentricity:
    """Return station `code`'s eccentricity whose span holds epoch `t` (Unix s).

    RecordError naming the file (`path`) when there is none, or several that disagree.
    """
    mine = [e for e in eccentricities if e.code == code]
    hit = [e for e in mine if _covers(e.start, e.end, t)]
    if hit and all(np.array_equal(h.une_m, hit[0].une_m) for h in hit):
        return hit[0]
    if not mine:
        raise RecordError(f"{path}: no SITE/ECCENTRICITY of station {shown(code)}")
    what = "no eccentricity" if not hit else f"{len(hit)} different eccentricities"
    raise RecordError(f"{path}: station {shown(code)}: {what} for {iso(t)} (lines "
                      + ", ".join(str(e.line) for e in (hit or mine)[:6]) + ")")


def _span(start: float | None, end: float | None) -> str:
    """Return a span as text ("2004-08-07 .. open")."""
    return f"{iso(start)[:10] if start else 'open'} .. {iso(end)[:10] if end else 'open'}"
