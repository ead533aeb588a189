"""Reading one of the field's files within a bound on its size.

A reader of a small file (a sites file, a parameters file) refuses one larger than it can
hold before it parses anything: `read_bounded` reads at most one byte past the bound, so a
file of any size (or a device that never ends) costs that much memory at most.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["read_bounded"]


def read_bounded(path: Path | str, max_bytes: int) -> bytes | None:
    """Return the bytes of the file at `path`, or None when it holds more than `max_bytes`.

    Reads at most ``max_bytes + 1`` bytes. OSError as opening or reading the file raises it.
    """
    with Path(path).open("rb") as f:
        raw = f.read(max_bytes + 1)
    return None if len(raw) > max_bytes else raw
