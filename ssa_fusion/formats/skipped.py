"""Element sets a read that keeps going leaves out: `Skipped`, one line each.

A real catalog always carries a few element sets that cannot be used (a B* beyond any
physical drag term, a checksum that fails, an object twice). A read given a `Skipped`
(`element_sets.read_catalog`'s ``skip``) leaves each such set out with one line naming the
file, the line, the object and the reason, counts it, and goes on with the next; without
one (strict) the first such set refuses the whole file, as a ValueError of the same words.
Errors of the file itself (unreadable, not text, an unknown format, XML that is not well
formed) refuse it either way.
"""

from __future__ import annotations

from dataclasses import dataclass, field

MAX_LINES = 1000
"""Lines kept (the rest counted only): a file of bad sets does not fill the memory."""


@dataclass
class Skipped:
    """The element sets a read left out.

    Attributes
    ----------
    count : int
        How many.
    lines : list of str
        One line each, ``file:line: object ID (NAME): reason; skipped``, the first
        `MAX_LINES` of them.
    """

    count: int = 0
    lines: list[str] = field(default_factory=list)

    def add(self, where: str, object_id: str, name: str, reason: str) -> None:
        """Count a set left out at `where` (``file:line``), of `object_id` and `name`."""
        self.count += 1
        if len(self.lines) < MAX_LINES:
            who = f"object {object_id or '?'}" + (f" ({name})" if name else "")
            self.lines.append(f"{where}: {who}: {reason}; skipped")

    def summary(self) -> str:
        """Return the lines, and how many more were left out, as text."""
        more = self.count - len(self.lines)
        return "\n".join([*self.lines, *([f"... and {more} more"] if more > 0 else [])])


def skip_or_raise(skip: Skipped | None, exc: ValueError, where: str, object_id: str,
                  name: str = "") -> None:
    """Raise `exc` when `skip` is None (strict); else count its set as left out there.

    `exc`'s message is ``file:line: reason`` (the readers' errors): the reason is what
    follows, and the line the one it names (a set's line 2, say) where it names one of the
    file `where` names.
    """
    if skip is None:
        raise exc
    text = str(exc)
    source = where.rsplit(":", 1)[0]
    at, _, reason = text[len(source) + 1:].partition(": ")
    if text.startswith(f"{source}:") and reason and (at.isdigit() or at.startswith("segment ")):
        skip.add(f"{source}:{at}", object_id, name, reason)
    else:
        skip.add(where, object_id, name, text.removeprefix(f"{source}: "))
