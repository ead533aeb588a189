"""Checks an element set of either format (TLE or OMM) passes before it is taken.

The domains of `element_sets`' module docstring: SGP4 accepts the element set, its angles
are finite, the inclination in [0, 180] deg, the eccentricity in [0, 1), the mean motion
that of a bound orbit above the Earth's surface, |B*| at most `MAX_BSTAR`, the epoch one
ssa_fusion represents, a catalogue number above 0; a name of at most `MAX_NAME` characters
without control characters; an object once per file.
Errors are ValueError naming the place (``file:line``), values quoted to `MAX_QUOTE`
characters. Units: SGP4's (rad, rad/min, 1/Earth radii), epochs Unix s UTC.
"""

from __future__ import annotations

import math
import unicodedata
from collections.abc import Iterable, Iterator

from sgp4.api import SGP4_ERRORS, Satrec

from ssa_fusion.core.earth.timescales import DAY_S, UNIX_EPOCH_JD, check_epochs
from ssa_fusion.core.motion.element_sets import CatalogEntry

__all__ = ["MAX_BSTAR", "MAX_MEAN_MOTION_REV_DAY", "MAX_NAME", "MAX_QUOTE", "check_name",
           "check_new", "check_satrec", "numbered", "quote"]

MAX_QUOTE = 60
"""Characters of a value quoted in an error message (the rest is cut: '...')."""
MAX_NAME = 128
"""Longest object name taken (a 3LE name line is 24 characters, an OMM OBJECT_NAME as long;
`validation.MAX_ID_CHARS` is as long)."""


MAX_MEAN_MOTION_REV_DAY = 18.0
"""The largest mean motion taken, rev/day: 17 rev/day is an orbit at the Earth's surface."""


MAX_BSTAR = 1.0
"""The largest |B*| taken, 1/Earth radii (decaying debris reach ~0.1; 1 is implausible)."""


def quote(value: object) -> str:
    """``repr`` of `value`, cut to `MAX_QUOTE` characters."""
    text = repr(value)
    return text if len(text) <= MAX_QUOTE else text[:MAX_QUOTE] + "..."


def check_name(name: str, where: str) -> None:
    """Refuse an object name longer than `MAX_NAME` characters or with control characters.

    NUL, escape (terminal control sequences) and the other C0/C1 controls would be stored in
    bags and echoed raw to a user's terminal (ValueError naming `where`).
    """
    if len(name) > MAX_NAME:
        raise ValueError(f"{where}: an object name of {len(name)} characters (at most "
                         f"{MAX_NAME}): {quote(name)}")
    if any(unicodedata.category(c) == "Cc" for c in name):
        raise ValueError(f"{where}: an object name with control characters (NUL, escape, "
                         f"...): {quote(name)}")


def numbered(lines: Iterable[str]) -> Iterator[tuple[int, str]]:
    """(1-based line number, line without trailing blanks), comments and blanks left out."""
    for no, raw in enumerate(lines, 1):
        line = raw.rstrip()
        if line and not line.startswith("#"):
            yield no, line


def check_new(entry: CatalogEntry, seen: dict[str, str]) -> None:
    """Refuse an object already in `seen` (id -> where); else add it (ValueError naming both)."""
    if entry.object_id in seen:
        raise ValueError(f"{entry.source}: object {entry.object_id} is already in the "
                         f"catalog ({seen[entry.object_id]}); one element set per object")
    seen[entry.object_id] = entry.source


def check_satrec(sat: Satrec, where: str) -> None:
    """ValueError if SGP4 refused the element set, or a field is outside its domain.

    The domains are the module docstring's; the epoch must lie in the frames' range.
    """
    if sat.error:
        raise ValueError(f"{where}: SGP4 refuses the element set: "
                         f"{SGP4_ERRORS.get(sat.error, f'error {sat.error}')}")
    if sat.satnum < 1:
        raise ValueError(f"{where}: catalogue number 0 is no object's (NORAD catalogue "
                         f"numbers start at 1)")
    fields = {"inclination": sat.inclo, "right ascension of the node": sat.nodeo,
              "argument of perigee": sat.argpo, "mean anomaly": sat.mo,
              "eccentricity": sat.ecco, "mean motion": sat.no_kozai, "B*": sat.bstar,
              "mean motion derivative": sat.ndot, "its second derivative": sat.nddot}
    bad = [k for k, v in fields.items() if not math.isfinite(v)]
    if bad:
        raise ValueError(f"{where}: {', '.join(bad)} not finite")
    rev_day = sat.no_kozai * 1440.0 / (2.0 * math.pi)
    if not 0.0 <= sat.inclo <= math.pi:
        raise ValueError(f"{where}: inclination {math.degrees(sat.inclo):g} deg outside "
                         f"[0, 180]")
    if not (0.0 < rev_day <= MAX_MEAN_MOTION_REV_DAY and 0.0 <= sat.ecco < 1.0):
        raise ValueError(f"{where}: not a bound orbit above the Earth's surface (mean motion "
                         f"{rev_day:g} rev/day, eccentricity {sat.ecco:g})")
    if abs(sat.bstar) > MAX_BSTAR:
        raise ValueError(f"{where}: B* {sat.bstar:g} per Earth radius beyond "
                         f"{MAX_BSTAR:g} (not a physical drag term)")
    epoch = float((sat.jdsatepoch - UNIX_EPOCH_JD) * DAY_S + sat.jdsatepochF * DAY_S)
    check_epochs(epoch, f"{where}: epoch")
