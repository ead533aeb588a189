"""Earth-orientation parameters (EOP): UT1 - UTC and polar motion, from IERS tables.

`EarthOrientation` holds a daily table of UT1 - UTC (s) and the pole coordinates x_p, y_p
(rad) and interpolates them linearly, as astropy and Orekit do (UT1 - UTC is interpolated as
UT1 - TAI, which has no leap-second jumps). Where it comes from:

* `bundled()`: the IERS ``finals2000A.all`` that `astropy-iers-data` ships (offline):
  Bulletin B values where final, Bulletin A values and a year of predictions after them.
* `read_finals(path)`: a user's own ``finals2000A.all``/``finals2000A.data``/``finals.daily``
  (the same fixed-width format, from the IERS or USNO).
* `NO_EOP`: UT1 = UTC and no polar motion. The size of that error: |UT1 - UTC| < 0.9 s by the
  definition of UTC, so the Earth's rotation is off by up to 0.9 s x 7.29e-5 rad/s = 6.6e-5
  rad (13.5"): up to ~0.42 km along the equator for a site or an Earth-fixed point and
  ~0.45 km for a LEO object mapped between inertial and Earth-fixed frames; polar motion
  adds < 0.6" (~20 m at the Earth's surface).

`default()` is what frames use unless told otherwise: the environment variable
``SSA_FUSION_EOP`` set to ``none`` (`NO_EOP`), to a file (`read_finals`), or unset (the bundled
table). Outside its table's span an `EarthOrientation` gives the no-EOP values (and
`covers` says so). The CIP offsets dX, dY of the tables (< 1 mas, a centimetre at the
Earth's surface) are not applied.
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.constants import ARCSEC
from ssa_fusion.core.earth.timescales import DAY_S, UNIX_EPOCH_JD, tai_minus_utc

Array = NDArray[np.float64]

MJD_JD = 2400000.5
"""Julian date of MJD 0."""

EOP_ENV = "SSA_FUSION_EOP"
"""Environment variable choosing the EOP: unset (bundled), ``none``, or a finals2000A file."""


@dataclass(frozen=True)
class EopValues:
    """EOP at some epochs (arrays of the epochs' shape).

    Attributes
    ----------
    dut1 : ndarray
        UT1 - UTC, s.
    xp, yp : ndarray
        Pole coordinates, rad.
    covered : ndarray of bool
        True where the table covers the epoch (else the values are the no-EOP zeros).
    """

    dut1: Array
    xp: Array
    yp: Array
    covered: NDArray[np.bool_]


@dataclass(frozen=True, eq=False)
class EarthOrientation:
    """A daily EOP table, interpolated linearly (see the module docstring).

    Attributes
    ----------
    t : ndarray (n,)
        Epochs of the rows, Unix s (0h UTC of each day), increasing.
    ut1_tai : ndarray (n,)
        UT1 - TAI, s (UT1 - UTC minus the leap seconds).
    xp, yp : ndarray (n,)
        Pole coordinates, rad.
    source : str
        Where the table came from ("none" for `NO_EOP`).
    """

    t: Array
    ut1_tai: Array
    xp: Array
    yp: Array
    source: str
    _key: int = field(default=0, repr=False)

    def __post_init__(self) -> None:
        """Check the table's shape and order (ValueError)."""
        n = len(self.t)
        if not (len(self.ut1_tai) == len(self.xp) == len(self.yp) == n):
            raise ValueError("EOP columns of different lengths")
        if n and not np.all(np.diff(self.t) > 0):
            raise ValueError(f"{self.source}: EOP epochs not increasing")
        object.__setattr__(self, "_key", id(self))

    @property
    def span(self) -> tuple[float, float]:
        """First and last epoch of the table, Unix s ((inf, -inf) for `NO_EOP`)."""
        if not len(self.t):
            return math.inf, -math.inf
        return float(self.t[0]), float(self.t[-1])

    def covers(self, t_unix: ArrayLike) -> NDArray[np.bool_]:
        """Return True where the table covers the epochs (else the no-EOP values serve)."""
        t = np.asarray(t_unix, dtype=float)
        lo, hi = self.span
        out: NDArray[np.bool_] = (t >= lo) & (t <= hi)
        return out

    def at(self, t_unix: ArrayLike) -> EopValues:
        """UT1 - UTC (s), x_p and y_p (rad) at Unix stamps, linearly interpolated."""
        t = np.asarray(t_unix, dtype=float)
        covered = self.covers(t)
        if not len(self.t):
            zero = np.zeros(t.shape)
            return EopValues(zero, zero, zero.copy(), covered)
        ut1_tai = np.interp(t, self.t, self.ut1_tai)
        dut1 = np.where(covered, ut1_tai + tai_minus_utc(t), 0.0)
        xp = np.where(covered, np.interp(t, self.t, self.xp), 0.0)
        yp = np.where(covered, np.interp(t, self.t, self.yp), 0.0)
        return EopValues(dut1, xp, yp, covered)


NO_EOP = EarthOrientation(np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0), "none")
"""UT1 = UTC, no polar motion (the module docstring gives the size of that error)."""


def _column(lines: list[str], a: int, b: int) -> Array:
    """Float column at 1-based bytes a..b of fixed-width lines (NaN where blank)."""
    out = np.full(len(lines), np.nan)
    for i, line in enumerate(lines):
        s = line[a - 1:b].strip()
        if s:
            out[i] = float(s)
    return out


def read_finals(path: Path | str) -> EarthOrientation:
    """Read an IERS ``finals2000A`` file (all, data or daily): UT1 - UTC and polar motion.

    Bulletin B values are used where the row has them, else Bulletin A (observed or
    predicted); rows with neither UT1 - UTC nor polar motion end the table. ValueError
    naming the file and line for a row that cannot be read.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="ascii", errors="strict")
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: cannot read an IERS finals file: {exc}") from None
    lines = [ln for ln in text.splitlines() if ln.strip()]
    try:
        mjd = _column(lines, 8, 15)
        xa, ya, ua = _column(lines, 19, 27), _column(lines, 38, 46), _column(lines, 59, 68)
        xb, yb, ub = _column(lines, 135, 144), _column(lines, 145, 154), _column(lines, 155, 165)
    except ValueError as exc:
        raise ValueError(f"{path}: not an IERS finals2000A file ({exc})") from None
    x, y, u = (np.where(np.isnan(b), a, b) for a, b in ((xa, xb), (ya, yb), (ua, ub)))
    good = ~(np.isnan(mjd) | np.isnan(u) | np.isnan(x) | np.isnan(y))
    if not good.any():
        raise ValueError(f"{path}: no row with UT1-UTC and polar motion (not a finals2000A "
                         f"file?)")
    last = int(np.flatnonzero(good)[-1]) + 1
    first = int(np.flatnonzero(good)[0])
    keep = slice(first, last)
    if not good[keep].all():
        bad = first + int(np.flatnonzero(~good[keep])[0])
        raise ValueError(f"{path}:{bad + 1}: row without UT1-UTC or polar motion inside the "
                         f"table")
    t = (mjd[keep] + MJD_JD - UNIX_EPOCH_JD) * DAY_S
    return EarthOrientation(t, u[keep] - tai_minus_utc(t), x[keep] * ARCSEC, y[keep] * ARCSEC,
                            str(path))


@functools.cache
def bundled() -> EarthOrientation:
    """Return the IERS finals2000A table of astropy-iers-data (read once per process)."""
    import astropy_iers_data

    return read_finals(astropy_iers_data.IERS_A_FILE)


@functools.cache
def _from_env(value: str) -> EarthOrientation:
    if value.lower() == "none":
        return NO_EOP
    return read_finals(value)


def default() -> EarthOrientation:
    """Return the default EOP: ``SSA_FUSION_EOP`` (none, a file) or the bundled table."""
    value = os.environ.get(EOP_ENV, "").strip()
    return _from_env(value) if value else bundled()
