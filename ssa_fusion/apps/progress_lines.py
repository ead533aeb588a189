"""Lines on stderr saying how far a long read (or write) of a command has got.

`import tdm` reading a TDM and writing its bag, `live` reading a catalog or an element set
file: one line every few seconds (the bytes read of the file's size and the items so far;
the items written of their total), none for work done sooner.
"""

from __future__ import annotations

import sys
import time
from typing import TextIO


class ProgressLines:
    """Lines on `stream` (stderr) saying how far `what` is, one every `every_s` seconds at most.

    ``what: read 12.3 of 100.0 MB (12%), 45000 objects, 5 s``: `what` names the command
    and its file, `items` what it counts. Nothing for work done within `every_s`: a small
    file says only the command's summary.
    """

    def __init__(self, what: str, items: str, every_s: float = 5.0,
                 stream: TextIO | None = None) -> None:
        self.what, self.items = what, items
        self.every_s = every_s
        self.stream = stream if stream is not None else sys.stderr
        self.t0 = self.last = time.monotonic()
        self.total = 0
        """The items `writing` writes in all."""

    def _due(self) -> bool:
        now = time.monotonic()
        if now - self.last < self.every_s:
            return False
        self.last = now
        return True

    def reading(self, done: int, size: int, items: int) -> None:
        """Say the bytes read of `size` and the items so far (if one is due)."""
        if self._due():
            self._say(f"read {done / 1e6:.1f} of {size / 1e6:.1f} MB "
                      f"({100.0 * done / max(size, 1):.0f}%), {items} {self.items}")

    def writing(self, done: int) -> None:
        """Say the items written of `total` (if one is due)."""
        if self._due():
            self._say(f"wrote {done} of {self.total} {self.items} to the bag "
                      f"({100.0 * done / max(self.total, 1):.0f}%)")

    def _say(self, what: str) -> None:
        print(f"{self.what}: {what}, {time.monotonic() - self.t0:.0f} s", file=self.stream,
              flush=True)
