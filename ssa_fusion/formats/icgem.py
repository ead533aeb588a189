"""ICGEM gravity-field files (``.gfc``): a geopotential model's coefficients, `read_icgem`.

The format of the International Centre for Global Earth Models (ICGEM, GFZ Potsdam; Barthelmes
& Köhler, *The ICGEM format*, 2009-2023): free text, then a header of ``keyword value`` lines
(``modelname``, ``earth_gravity_constant`` m^3/s^2, ``radius`` m, ``max_degree``,
``tide_system``, ``norm``: ``fully_normalized`` unless said otherwise, ``errors``), ended by a
line starting ``end_of_head``; then one ``gfc L M C S [sigma C sigma S]`` line per
coefficient (``gfct``/``trnd``/``acos``/``asin`` lines of time-variable models are refused:
only static fields are read). Fortran ``D`` exponents are accepted.

`egm96()` reads the EGM96 model shipped with ssa_fusion (``formats/data/egm96_to120.gfc``,
degree and order 120; its source and licence in ``formats/data/README.md``).

A header keyword missing or out of range, a coefficient line that is not ``gfc`` with
integers L >= M >= 0 and finite C, S, a degree above ``max_degree`` or a coefficient given
twice is refused with one line naming the file, the line and the field (`IcgemError`).
Units out: GM km^3/s^2, radius km (`geopotential.GravityField`).
"""

from __future__ import annotations

import functools
import math
from pathlib import Path

import numpy as np

from ssa_fusion.core.motion.geopotential import GravityField

__all__ = ["EGM96_FILE", "IcgemError", "egm96", "read_icgem"]

EGM96_FILE = Path(__file__).parent / "data" / "egm96_to120.gfc"
"""EGM96 to degree and order 120 (ICGEM format), shipped with the package."""

MAX_DEGREE = 2190
"""Highest degree read (EGM2008's); a header asking for more is refused."""

_STATIC = "gfc"
_REQUIRED = ("earth_gravity_constant", "radius", "max_degree")


class IcgemError(ValueError):
    """An ICGEM file that cannot be read: one line naming the file, line and field."""


def _number(text: str, path: Path, line: int, what: str) -> float:
    """Return ``text`` as a finite float (Fortran D exponents accepted), else IcgemError."""
    try:
        v = float(text.replace("D", "E").replace("d", "e"))
    except ValueError:
        raise IcgemError(f"{path}:{line}: {what}: not a number: {text[:40]!r}") from None
    if not math.isfinite(v):
        raise IcgemError(f"{path}:{line}: {what}: not finite: {text[:40]!r}")
    return v


def _header(lines: list[str], path: Path) -> tuple[dict[str, str], int]:
    """Return the header's keywords and the index of the first line after ``end_of_head``."""
    head: dict[str, str] = {}
    for i, raw in enumerate(lines):
        words = raw.split()
        if not words:
            continue
        if words[0] == "end_of_head":
            return head, i + 1
        if len(words) >= 2 and words[0] in (*_REQUIRED, "modelname", "tide_system", "norm",
                                            "errors", "product_type"):
            head[words[0]] = words[1]
    raise IcgemError(f"{path}: no end_of_head line: not an ICGEM file")


def _checked_header(head: dict[str, str], path: Path) -> tuple[float, float, int]:
    """GM (km^3/s^2), radius (km) and max degree of a header, checked."""
    for key in _REQUIRED:
        if key not in head:
            raise IcgemError(f"{path}: header: {key} missing")
    gm = _number(head["earth_gravity_constant"], path, 0, "earth_gravity_constant") * 1e-9
    radius = _number(head["radius"], path, 0, "radius") * 1e-3
    try:
        nmax = int(head["max_degree"])
    except ValueError:
        raise IcgemError(f"{path}: header: max_degree: not an integer") from None
    if not (gm > 0.0 and radius > 0.0 and 0 <= nmax <= MAX_DEGREE):
        raise IcgemError(f"{path}: header: earth_gravity_constant, radius > 0 and "
                         f"0 <= max_degree <= {MAX_DEGREE} needed")
    if head.get("norm", "fully_normalized") != "fully_normalized":
        raise IcgemError(f"{path}: header: norm {head['norm'][:40]!r}: only "
                         f"fully_normalized coefficients are read")
    return gm, radius, nmax


def read_icgem(path: Path | str, max_degree: int | None = None) -> GravityField:
    """Read an ICGEM ``.gfc`` file of a static gravity field (module docstring).

    Parameters
    ----------
    path : Path or str
        The file.
    max_degree : int, optional
        Keep the coefficients up to this degree only (default: all the file holds).

    Returns
    -------
    GravityField
        Fully normalised coefficients, GM km^3/s^2, radius km.
    """
    path = Path(path)
    try:
        lines = path.read_text(encoding="ascii", errors="strict").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise IcgemError(f"{path}: cannot read an ICGEM file: {exc}") from None
    head, start = _header(lines, path)
    gm, radius, nmax = _checked_header(head, path)
    keep = nmax if max_degree is None else min(nmax, int(max_degree))
    c = np.zeros((keep + 1, keep + 1))
    s = np.zeros((keep + 1, keep + 1))
    seen = np.zeros((keep + 1, keep + 1), dtype=bool)
    for i in range(start, len(lines)):
        words = lines[i].split()
        if not words:
            continue
        if words[0] != _STATIC or len(words) < 5:
            raise IcgemError(f"{path}:{i + 1}: key: a 'gfc L M C S' line expected, got "
                             f"{lines[i][:40]!r}")
        try:
            n, m = int(words[1]), int(words[2])
        except ValueError:
            raise IcgemError(f"{path}:{i + 1}: L, M: not integers") from None
        if not 0 <= m <= n <= nmax:
            raise IcgemError(f"{path}:{i + 1}: L, M: {n}, {m} not 0 <= M <= L <= {nmax}")
        if n > keep:
            continue
        if seen[n, m]:
            raise IcgemError(f"{path}:{i + 1}: L, M: coefficient {n}, {m} given twice")
        seen[n, m] = True
        c[n, m] = _number(words[3], path, i + 1, "C")
        s[n, m] = _number(words[4], path, i + 1, "S")
    return GravityField(head.get("modelname", path.stem), gm, radius, c, s,
                        head.get("tide_system", "unknown"))


@functools.cache
def egm96() -> GravityField:
    """Return EGM96 to degree and order 120 (the shipped file, read once per process)."""
    return read_icgem(EGM96_FILE)
