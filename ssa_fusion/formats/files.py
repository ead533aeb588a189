"""Reading one of the field's files within bounds: on its size, on the length of a line.

A reader of a small file (a sites file, a parameters file) refuses one larger than it can
hold before it parses anything: `read_bounded` reads at most one byte past the bound, so a
file of any size (or a device that never ends) costs that much memory at most. A reader of
a file of lines (a TDM in KVN, an ILRS file) takes it line by line, each read to a bound
(`raw_lines`): a line of any length costs that much memory at most.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO, NoReturn

__all__ = ["raw_lines", "read_bounded"]


def read_bounded(path: Path | str, max_bytes: int) -> bytes | None:
    """Return the bytes of the file at `path`, or None when it holds more than `max_bytes`.

    Reads at most ``max_bytes + 1`` bytes. OSError as opening or reading the file raises it.
    """
    with Path(path).open("rb") as f:
        raw = f.read(max_bytes + 1)
    return None if len(raw) > max_bytes else raw



def raw_lines(f: IO[bytes], max_line: int,
              fail: Callable[[OSError], NoReturn]) -> Iterator[bytes]:
    """Yield the lines of the binary file `f` as read, each of at most ``max_line + 2`` bytes.

    A longer line comes cut (the caller tells it by its length, its end of line missing);
    an OSError of the read goes to `fail`, which raises the reader's own error.
    """
    while True:
        try:
            raw = f.readline(max_line + 2)
        except OSError as exc:
            fail(exc)
        if not raw:
            return
        yield raw
