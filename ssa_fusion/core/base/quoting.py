"""Values and texts quoted in an error message, bounded: one line a user can read.

Every input reader (catalogs, TDM, sites and params files) names the offending value in its
error; the value may be a 100 MB line or a YAML alias bomb (a few hundred bytes that load as
a list of 10^8 items, whose ``repr`` would be gigabytes). `quote` gives a ``repr`` that
looks at a bounded part of the value only; `one_line` puts any text (an exception's message,
a line of the file) on one bounded line.
"""

from __future__ import annotations

import reprlib

MAX_QUOTE = 60
"""Characters of a value quoted in an error message (the rest is cut: '...')."""
MAX_MESSAGE = 400
"""Longest error message of a reader (one line a user can read), the file's path included
when the path is of ordinary length."""
_INT_BITS = 256
"""Integers longer than this many bits are said by their size (``repr`` of one of more
than 4300 digits raises ValueError)."""


class _Repr(reprlib.Repr):
    """`reprlib.Repr` with small limits and integers of any size."""

    def __init__(self) -> None:
        super().__init__()
        self.maxlevel = 3
        self.maxtuple = self.maxlist = self.maxarray = self.maxdeque = 4
        self.maxdict = self.maxset = self.maxfrozenset = 4
        self.maxstring = self.maxother = self.maxlong = MAX_QUOTE

    def repr_int(self, x: int, level: int) -> str:
        """``repr`` of an int; an enormous one by its size."""
        if x.bit_length() > _INT_BITS:
            return f"<{'-' if x < 0 else ''}integer of {x.bit_length()} bits>"
        return super().repr_int(x, level)


_REPR = _Repr()


def cut(text: str, limit: int = MAX_QUOTE) -> str:
    """Return `text` cut to `limit` characters ('...' ending it when it was cut)."""
    return text if len(text) <= limit else text[:max(0, limit - 3)] + "..."


def shown(text: str, limit: int = MAX_QUOTE) -> str:
    """Return `text` as it is if it is printable (no line breaks, tabs, controls), else quoted.

    Cut to `limit` characters either way.
    """
    return cut(text, limit) if text.isprintable() else quote(text, limit)


def quote(value: object, limit: int = MAX_QUOTE) -> str:
    """Return the ``repr`` of `value` on one line, at most `limit` characters.

    Containers are abbreviated (a few items, three levels deep: `reprlib`) without walking
    all of them, strings and other values cut, so a value of any size costs little.
    """
    try:
        text = _REPR.repr(value)
    except Exception:  # a value whose own __repr__ fails: say its type
        text = f"<{type(value).__name__}>"
    return cut(" ".join(text.split()), limit)


def one_line(text: object, limit: int = MAX_MESSAGE) -> str:
    """Return `text` (str() of it) on one line (whitespace runs made one space), cut to `limit`.

    Only the first ``4 * limit`` characters are looked at.
    """
    s = text if isinstance(text, str) else str(text)
    return cut(" ".join(s[:4 * limit].split()), limit)
