"""Text files of records, one a line (ILRS CRD and CPF, SINEX): read as a stream, checked.

`RecordLines` yields the non-blank lines of a file one at a time (never the whole file),
each checked before any reader looks at it: at most `MAX_LINE` bytes, UTF-8, no NUL and no
control character (a terminal escape, a form feed, a DEL: text a terminal or a log would
interpret). `Fields` reads the whitespace-separated fields of one line by position, each
checked for its kind and range: integers and decimal numbers (``1.5``, ``-.25E+07``,
``24.``; never ``nan``, ``inf``, ``1_000`` or a hexadecimal float, which Python's own
parsers take), words of bounded length, and the ``na`` of "not available" where the
format allows it.

Every problem raises `RecordError`, one bounded line naming the file, the line, the record
and the field: ``FILE:LINE: record 11: time of flight: -0.5 s outside (0, 10)``. Values
are quoted with `quoting.shown` (at most `quoting.MAX_QUOTE` characters, escapes shown as
escapes).
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path
from typing import NoReturn

from ssa_fusion.core.base.quoting import one_line, quote, shown
from ssa_fusion.formats.files import raw_lines

MAX_LINE = 1024
"""Longest line read, bytes (CRD and CPF lines are under 200, SINEX lines 80)."""
NOT_AVAILABLE = frozenset({"na", "-na"})
"""What ILRS v2 formats write for a value that is not available (any case)."""

_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eEdD][+-]?\d{1,3})?")
"""A decimal number as these formats write it (a Fortran ``D`` exponent too)."""
_INTEGER = re.compile(r"[+-]?\d{1,18}")
_CONTROL = re.compile(r"[\x00-\x08\x0a-\x1f\x7f-\x9f]")
"""Characters refused in a line: C0 and C1 controls and DEL (a tab is white space)."""


class RecordError(ValueError):
    """A file of records that cannot be read: one line naming the file, line and field."""


class RecordLines:
    """The non-blank lines of a text file of records, read as a stream and checked.

    Parameters
    ----------
    path
        The file.
    what
        What the file should be, for errors ("a CRD file").

    Iterating yields ``(line number, text)`` with trailing white space removed (leading
    white space kept: SINEX data lines start with a blank). `bytes_read` and `size` say
    how far it got.
    """

    def __init__(self, path: Path | str, what: str) -> None:
        self.path = Path(path)
        self.what = what
        try:
            self.size = self.path.stat().st_size
        except OSError as exc:
            self._fail_file(exc)
        self.bytes_read = 0
        self.line = 0

    def _fail_file(self, exc: OSError) -> NoReturn:
        raise RecordError(f"{shown(str(self.path), 200)}: cannot read: "
                          f"{exc.strerror or one_line(exc)}") from None

    def fail(self, line: int, what: str) -> NoReturn:
        """Raise the one-line `RecordError` of `what` at `line` (0: of the whole file)."""
        where = shown(str(self.path), 200) + (f":{line}" if line > 0 else "")
        raise RecordError(one_line(f"{where}: {what}"))

    def __iter__(self) -> Iterator[tuple[int, str]]:
        """Yield (line number, text) of every non-blank line, each checked."""
        try:
            f = self.path.open("rb")
        except OSError as exc:
            self._fail_file(exc)
        with f:
            for raw in raw_lines(f, MAX_LINE, self._fail_file):
                self.line += 1
                self.bytes_read += len(raw)
                text = self._checked(raw)
                if text.strip():
                    yield self.line, text

    def _checked(self, raw: bytes) -> str:
        """Return one raw line as text, refused if it is too long or not a text line."""
        n = self.line
        body = raw.rstrip(b"\r\n")
        if len(body) > MAX_LINE:
            self.fail(n, f"line longer than {MAX_LINE} bytes (starts "
                         f"{quote(body[:40].decode('utf-8', 'replace'))}): not {self.what}")
        if n == 1:
            body = body.removeprefix(b"\xef\xbb\xbf")
        try:
            text = body.decode("utf-8")
        except UnicodeDecodeError as exc:
            self.fail(n, f"not text (byte {exc.start + 1} of the line is not UTF-8): not "
                         f"{self.what}")
        bad = _CONTROL.search(text)
        if bad:
            name = "a NUL byte" if bad.group() == "\x00" else \
                f"control character {bad.group()!r}"
            self.fail(n, f"{name} at column {bad.start() + 1}: not {self.what}")
        return text.rstrip()


class Fields:
    """The whitespace-separated fields of one line, read by position with their checks.

    Parameters
    ----------
    lines
        The file the line is of (its errors name it).
    line
        The line number.
    text
        The line.
    record
        The record's name in errors ("record 11", "H4", "SOLUTION/ESTIMATE").
    """

    def __init__(self, lines: RecordLines, line: int, text: str, record: str) -> None:
        self.lines, self.line, self.record = lines, line, record
        self.tokens = text.split()

    @classmethod
    def columns(cls, lines: RecordLines, line: int, text: str, record: str,
                spans: tuple[tuple[int, int], ...]) -> Fields:
        """Return the fields of a fixed-format line: the text of each column span, stripped.

        `spans` are 0-based [start, end) character columns; field i is span i - 1. A line
        shorter than the last span's end is refused (truncated).
        """
        f = cls(lines, line, "", record)
        if len(text) < spans[-1][1]:
            f.fail(f"a line of {len(text)} characters, want {spans[-1][1]} (truncated?)")
        f.tokens = ["", *(text[a:b].strip() for a, b in spans)]
        return f

    def fail(self, what: str) -> NoReturn:
        """Raise the `RecordError` of `what` about this line's record."""
        self.lines.fail(self.line, f"{self.record}: {what}")

    def count(self, least: int, most: int | None = None) -> None:
        """Require `least` .. `most` fields after the record's own name (`most` None: any)."""
        n = len(self.tokens) - 1
        if n < least or (most is not None and n > most):
            want = f"{least}" if most == least else \
                f"{least} to {most}" if most is not None else f"at least {least}"
            self.fail(f"{n} field(s), want {want}" + (" (truncated?)" if n < least else ""))

    def raw(self, i: int, name: str) -> str:
        """Return field `i` (1 = the first after the record's name) as written."""
        if i >= len(self.tokens) or not self.tokens[i]:
            self.fail(f"{name}: missing (the line has {len(self.tokens) - 1} field(s))")
        return self.tokens[i]

    def word(self, i: int, name: str, longest: int = 64) -> str:
        """Return field `i` as a word of at most `longest` printable ASCII characters."""
        tok = self.raw(i, name)
        if len(tok) > longest or not tok.isascii() or not tok.isprintable():
            self.fail(f"{name}: {shown(tok)} is not a word of at most {longest} ASCII "
                      f"characters")
        return tok

    def is_na(self, i: int) -> bool:
        """Return whether field `i` says "not available" (``na``)."""
        return self.raw(i, "field").lower() in NOT_AVAILABLE

    def integer(self, i: int, name: str, lo: int, hi: int) -> int:
        """Return field `i` as an integer in [`lo`, `hi`]."""
        tok = self.raw(i, name)
        if not _INTEGER.fullmatch(tok):
            self.fail(f"{name}: {shown(tok)} is not an integer")
        v = int(tok)
        if not lo <= v <= hi:
            self.fail(f"{name}: {v} outside [{lo}, {hi}]")
        return v

    def optional_integer(self, i: int, name: str, lo: int, hi: int) -> int | None:
        """Return field `i` as an integer in [`lo`, `hi`], or None for ``na``."""
        return None if self.is_na(i) else self.integer(i, name, lo, hi)

    def number(self, i: int, name: str, lo: float, hi: float, unit: str = "") -> float:
        """Return field `i` as a finite decimal number in [`lo`, `hi`] (`unit` for errors)."""
        tok = self.raw(i, name)
        if not _NUMBER.fullmatch(tok):
            self.fail(f"{name}: {shown(tok)} is not a decimal number")
        v = float(tok.replace("D", "E").replace("d", "e"))
        if not lo <= v <= hi:
            u = f" {unit}" if unit else ""
            self.fail(f"{name}: {shown(tok)}{u} outside [{lo:g}, {hi:g}]{u}")
        return v

    def optional_number(self, i: int, name: str, lo: float, hi: float,
                        unit: str = "") -> float | None:
        """Return field `i` as a number in [`lo`, `hi`], or None for ``na``."""
        return None if self.is_na(i) else self.number(i, name, lo, hi, unit)

    def flag(self, i: int, name: str) -> bool:
        """Return field `i`, 0 or 1, as a bool."""
        return self.integer(i, name, 0, 1) == 1
