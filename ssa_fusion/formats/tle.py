"""TLE and 3LE element sets, checked column by column (`element_sets` module docstring).

Two lines per object, or a name line then the two lines (a Space-Track ``0 NAME`` name line
works too); lines starting with ``#`` and blank lines are skipped. Every line is checked
against the TLE layout (`sgp4.io.LINE1`/`LINE2`) and by its checksum (column 69, when
present), because ``Satrec.twoline2rv`` accepts malformed lines silently (zeros for what it
cannot read); the epoch's day of the year must be one.
"""

from __future__ import annotations

import calendar
import re
from collections.abc import Iterator

from sgp4.api import Satrec
from sgp4.io import LINE1, LINE2

from ssa_fusion.core.motion.element_sets import CatalogEntry
from ssa_fusion.formats.element_set_checks import (
    check_name,
    check_new,
    check_satrec,
    numbered,
    quote,
)
from ssa_fusion.formats.skipped import Skipped, skip_or_raise

__all__ = ["check_columns", "parse_tle", "tle_entries"]


_ALPHA5 = "ABCDEFGHJKLMNPQRSTUVWXYZ"
"""Alpha-5's first characters (I and O are not used)."""


def parse_tle(text: str, source: str = "<string>",
              skip: Skipped | None = None) -> list[CatalogEntry]:
    """Entries of TLE/3LE `text` (see the module docstring); `source` names it in errors.

    `skip`: leave bad element sets out and count them there (`formats.skipped`).
    """
    return list(tle_entries(numbered(text.splitlines()), source, skip))


def tle_entries(lines: Iterator[tuple[int, str]], source: str,
                skip: Skipped | None = None) -> Iterator[CatalogEntry]:
    """Yield the entries of TLE/3LE `lines` (numbered, as `numbered` yields them).

    A bad element set (its name line, its two lines, or a line out of place) raises, or
    with `skip` is counted there and left out: the read goes on at the next line that can
    start a set.
    """
    seen: dict[str, str] = {}
    name, name_no, bad_name = "", 0, None
    back: list[tuple[int, str]] = []  # a line read ahead, to be read again
    while (item := back.pop() if back else next(lines, None)) is not None:
        no, line = item
        where = f"{source}:{no}"
        if line.startswith("1 "):
            nxt = next(lines, None)
            try:
                if nxt is None or not nxt[1].startswith("2 "):
                    if nxt is not None:
                        back.append(nxt)
                    raise ValueError(f"{where}: TLE line 1 is not followed by its line 2")
                if bad_name is not None:
                    raise bad_name
                entry = _tle_entry(line, nxt[1], name, where, f"{source}:{nxt[0]}")
                check_new(entry, seen)
            except ValueError as exc:
                skip_or_raise(skip, exc, where if bad_name is None else f"{source}:{name_no}",
                              line[2:7].strip(), name)
            else:
                yield entry
            name, name_no, bad_name = "", 0, None
        elif line.startswith("2 "):
            skip_or_raise(skip, ValueError(f"{where}: TLE line 2 without a line 1 before it"),
                          where, line[2:7].strip())
        elif name or bad_name is not None:
            skip_or_raise(skip, bad_name or ValueError(
                f"{source}:{name_no}: name line {quote(name)} is not followed by TLE lines "
                f"(line {no} is neither)"), f"{source}:{name_no}", "", name)
            name, name_no, bad_name = "", 0, None
            back.append(item)
        else:
            name, name_no = (line[2:] if line.startswith("0 ") else line).strip(), no
            try:
                check_name(name, f"{where}: name line")
            except ValueError as exc:
                if skip is None:
                    raise
                bad_name, name = exc, ""  # not echoed: its own error quotes it, bounded
    if name or bad_name is not None:
        skip_or_raise(skip, bad_name or ValueError(
            f"{source}:{name_no}: name line {quote(name)} at the end of the file without "
            f"TLE lines"), f"{source}:{name_no}", "", name)


def check_columns(line: str, template: str, which: int, where: str) -> None:
    """ValueError unless `line` fits the TLE layout `template` (sgp4.io.LINE1/LINE2)."""
    if not line.isascii():
        raise ValueError(f"{where}: TLE line {which} has non-ASCII characters")
    if len(line) not in (68, 69):  # 68: without the checksum column
        raise ValueError(f"{where}: TLE line {which} has {len(line)} columns, not 69")
    number = line[2:7]
    if not ((number.strip().isdigit() and number == number.strip().rjust(5))
            or (number[0] in _ALPHA5 and number[1:].isdigit())):
        raise ValueError(f"{where}: TLE line {which}, columns 3-7: catalogue number "
                         f"{number!r} is neither digits nor Alpha-5 (a letter, 4 digits)")
    if _LAYOUTS[template].fullmatch(line) is None:  # then say which column, and why
        for col, (c, want) in enumerate(zip(line, template, strict=False), 1):
            if not _fits(c, want, col):
                raise ValueError(f"{where}: TLE line {which}, column {col}: {c!r} does not "
                                 f"fit the TLE layout ({want!r} there)")
    if len(line) == 69 and int(line[68]) != (total := _checksum(line)):
        raise ValueError(f"{where}: TLE line {which} fails its checksum (column 69 is "
                         f"{line[-1]!r}, the line sums to {total})")


def _fits(c: str, want: str, col: int) -> bool:
    """Whether character `c` fits column `col` (from 1) of a TLE layout, which has `want`."""
    if 3 <= col <= 7:  # the catalogue number, checked on its own
        return True
    if want == "N":
        return c.isdigit() or c == " "
    if want in "+-":
        return c in " +-" or (want == "-" and c.isdigit())
    if want in " .12":
        return c == want
    return True  # classification, international designator: free text


def _layout(template: str) -> re.Pattern[str]:
    """Return the pattern of the ASCII lines of 68 or 69 columns that `_fits` `template`."""
    ascii_chars = [chr(i) for i in range(128)]
    columns = []
    for col, want in enumerate(template, 1):
        fit = [c for c in ascii_chars if _fits(c, want, col)]
        columns.append("." if len(fit) == len(ascii_chars) else
                       "[" + "".join(re.escape(c) for c in fit) + "]")
    return re.compile("".join(columns[:68]) + f"(?:{columns[68]})?", re.DOTALL)


_LAYOUTS = {LINE1: _layout(LINE1), LINE2: _layout(LINE2)}
"""The TLE layouts' patterns (`check_columns` says where a line that fails one fails)."""


_CHECKSUM_VALUES = bytes(i - 48 if 48 <= i <= 57 else int(i == 45) for i in range(256))
"""What an ASCII character adds to a TLE line's checksum: a digit its value, '-' one."""


def _checksum(line: str) -> int:
    """Return the checksum of an ASCII TLE line (as `sgp4.io.compute_checksum`)."""
    return sum(line[:68].encode("ascii").translate(_CHECKSUM_VALUES)) % 10


def _tle_entry(line1: str, line2: str, name: str, where: str, where2: str) -> CatalogEntry:
    """Entry of TLE lines `line1` (at `where`, ``file:line``) and `line2` (at `where2`)."""
    check_columns(line1, LINE1, 1, where)
    check_columns(line2, LINE2, 2, where2)
    if line1[2:7] != line2[2:7]:
        raise ValueError(f"{where}: catalogue numbers of lines 1 and 2 differ "
                         f"({line1[2:7]!r} and {line2[2:7]!r})")
    _check_epoch_day(line1, where)
    sat = Satrec.twoline2rv(line1, line2)
    check_satrec(sat, where)
    return CatalogEntry(str(sat.satnum), name, sat, where)


def _check_epoch_day(line1: str, where: str) -> None:
    """ValueError unless line 1's epoch (columns 19-32, YYDDD.DDDDDDDD) has a day in 1-366.

    SGP4 reads day 999 or 000 of a year as days past or before it without a word, and day
    366 of a common year as the next 1 January: each is refused (days 1-365 of a common
    year, 1-366 of a leap year).
    """
    yy = int(line1[18:20])
    year = 1900 + yy if yy >= 57 else 2000 + yy  # the TLE convention
    days = 366 if calendar.isleap(year) else 365
    try:
        day = float(line1[20:32])
    except ValueError:
        raise ValueError(f"{where}: TLE line 1, columns 21-32: epoch day "
                         f"{line1[20:32]!r} is not a number") from None
    if not 1.0 <= day < days + 1.0:
        raise ValueError(f"{where}: TLE line 1, columns 19-32: day {day:g} of {year} is "
                         f"not in 1-{days}.999...")
