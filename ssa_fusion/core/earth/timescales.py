"""Time scales: UTC stamps, and the TAI, TT and UT1 that frames and dynamics need (pyerfa).

Every stamp in ssa_fusion is **UTC**, as ROS time is: Unix seconds ``t`` (POSIX time: UTC
days times 86400 plus the seconds of the day, a leap second folded into the next second), so
the UTC Julian date is ``UNIX_EPOCH_JD + t / 86400`` exactly. Internally each use converts
explicitly:

* **TAI** = UTC + (TAI - UTC), the leap seconds of the IERS table (`erfa.dat`, its table
  brought up to date from the IERS ``Leap_Second.dat`` that `astropy-iers-data` ships, as
  astropy does);
* **TT** = TAI + 32.184 s: the argument of precession-nutation (`frames`) and of the Sun's
  ephemeris; elapsed dynamical time between two stamps is their difference in TT
  (`tt_elapsed`), which differs from the difference of the stamps only across a leap second;
* **UT1** = UTC + (UT1 - UTC), ``dut1`` from the Earth-orientation parameters (`eop`): the
  argument of the Earth rotation angle and of GMST.

Julian dates are returned as two parts ``(jd1, jd2)`` with ``jd1`` the whole day
(``xxxx.5``) and ``jd2`` the fraction, as ERFA wants them: one float64 Julian date resolves
only ~40 us, which is 20 m of Earth rotation at a satellite's distance.

The range a stamp may take is `EPOCH_MIN` .. `EPOCH_MAX` (UTC, 1972-01-01 to
2038-01-19T03:14:07): from the start of the leap seconds (TAI - UTC a whole number of seconds,
IERS tables) to the last second a ROS 2 time stamp can carry (``builtin_interfaces/Time``
has int32 seconds: a later stamp would wrap to 1901). `check_epochs` refuses a stamp outside
it with one line naming it, at every entrance (element sets, TDM files, messages).
"""

from __future__ import annotations

import functools
import math
import warnings
from datetime import UTC, datetime
from pathlib import Path

import erfa
import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

UNIX_EPOCH_JD = 2440587.5
"""Julian date (UTC) of 1970-01-01T00:00:00 UTC; jd_utc = UNIX_EPOCH_JD + t_unix / 86400."""

DAY_S = 86400.0
"""Seconds per (UTC or TT) day."""

TT_MINUS_TAI = 32.184
"""TT - TAI, s (exact by definition)."""

EPOCH_MIN = 63072000.0
"""Earliest stamp the frames take: 1972-01-01T00:00:00 UTC (Unix s), the start of leap
seconds (before it TAI - UTC drifted continuously)."""

EPOCH_MAX = 2147483647.0
"""Latest stamp: 2038-01-19T03:14:07 UTC (Unix s), the largest int32 second of a ROS 2 stamp."""


def iso(t_unix: float) -> str:
    """Return UTC ISO 8601 of a Unix stamp (s), e.g. ``2025-01-01T00:00:00.000Z``."""
    if not math.isfinite(t_unix) or abs(t_unix) > 1e11:
        return f"t={t_unix!r} s"
    dt = datetime.fromtimestamp(t_unix, tz=UTC)
    return dt.strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"


def parse_utc(text: str) -> float:
    """Return the Unix stamp (s) of an ISO 8601 epoch, UTC unless it names a zone offset.

    E.g. ``2025-06-01T00:00:00Z``, ``2025-06-01 12:30``, ``2025-06-01``. ValueError with
    one line when `text` is not ISO 8601 or lies outside `EPOCH_MIN` .. `EPOCH_MAX`.
    """
    try:
        dt = datetime.fromisoformat(text.strip())
    except ValueError:
        raise ValueError(f"{text!r} is not an ISO 8601 epoch (e.g. 2025-06-01T00:00:00Z)") \
            from None
    t = (dt if dt.tzinfo is not None else dt.replace(tzinfo=UTC)).timestamp()
    check_epochs(t)
    return t


def check_epochs(t_unix: ArrayLike, what: str = "epoch") -> None:
    """Raise ValueError unless every stamp is finite and within `EPOCH_MIN` .. `EPOCH_MAX`."""
    t = np.asarray(t_unix, dtype=float)
    bad = ~np.isfinite(t) | (t < EPOCH_MIN) | (t > EPOCH_MAX)
    if np.any(bad):
        first = float(t.ravel()[np.flatnonzero(bad.ravel())[0]])
        raise ValueError(f"{what} {iso(first)} is outside the range ssa_fusion represents "
                         f"({iso(EPOCH_MIN)} .. {iso(EPOCH_MAX)}: leap seconds to the last "
                         f"second of a ROS 2 stamp)")


def check_window(t0: float, span_s: float) -> None:
    """Raise ValueError (one line) unless a run's start and end are representable epochs.

    `t0`: the start (Unix s); `span_s`: its length (s); both ends go to `check_epochs`.
    """
    check_epochs([t0], "start")
    check_epochs([t0 + span_s], "the run's end (start + duration)")


@functools.cache
def install_leap_seconds() -> str:
    """Bring ERFA's leap-second table up to date from astropy-iers-data's IERS file.

    Done once per process, before any conversion (every function here calls it); returns
    the file used ("" when the package is missing: ERFA's built-in table then serves,
    correct through its own release).
    """
    try:
        import astropy_iers_data
    except ImportError:  # pragma: no cover - a dependency of the project
        return ""
    path = Path(astropy_iers_data.IERS_LEAP_SECOND_FILE)
    rows = []
    expires = None
    for line in path.read_text().splitlines():
        if "File expires on" in line:
            expires = datetime.strptime(line.split("on", 1)[1].strip(), "%d %B %Y")
        parts = line.split()
        if line.startswith("#") or len(parts) != 5:
            continue
        _mjd, day, month, year, tai_utc = parts
        rows.append((int(year), int(month), int(day), float(tai_utc)))
    table = np.array(rows, dtype=[("year", "i4"), ("month", "i4"), ("day", "i4"),
                                  ("tai_utc", "f8")]).view(np.recarray)
    erfa.leap_seconds.update(table)
    if expires is not None and expires > erfa.leap_seconds.expires:
        erfa.leap_seconds._expires = expires  # what update() does for a table that says so
    return str(path)


def jd_utc(t_unix: ArrayLike) -> tuple[Array, Array]:
    """Two-part UTC Julian date ``(jd1, jd2)`` of Unix stamps (s); jd1 the whole days."""
    t = np.asarray(t_unix, dtype=float)
    days = np.floor(t / DAY_S)
    return UNIX_EPOCH_JD + days, (t - days * DAY_S) / DAY_S


def tai_minus_utc(t_unix: ArrayLike) -> Array:
    """TAI - UTC, s, at Unix stamps (the leap seconds; `erfa.utctai`).

    Taken at 0h UTC of each stamp's day: a Unix stamp counts 86400 s in every day, while
    ERFA's UTC day fraction of a leap-second day is of 86401 s, and TAI - UTC changes only at
    a day's end. Beyond the table's last leap second (+ 5 years ERFA calls the year
    "dubious") no new leap second is known: TAI - UTC stays at its last value, silently.
    """
    install_leap_seconds()
    u1, _ = jd_utc(t_unix)
    days, inverse = np.unique(u1, return_inverse=True)  # one ERFA call per distinct day
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", erfa.ErfaWarning)
        a1, a2 = erfa.utctai(days, np.zeros_like(days))
    out: Array = np.round(((a1 - days) + a2) * DAY_S, 6)[inverse.reshape(u1.shape)]
    return out


def tt_minus_utc(t_unix: ArrayLike) -> Array:
    """TT - UTC, s (32.184 s + the leap seconds)."""
    out: Array = tai_minus_utc(t_unix) + TT_MINUS_TAI
    return out


def jd_tt(t_unix: ArrayLike) -> tuple[Array, Array]:
    """Two-part TT Julian date of Unix (UTC) stamps."""
    u1, u2 = jd_utc(t_unix)
    return u1, u2 + tt_minus_utc(t_unix) / DAY_S


def jd_ut1(t_unix: ArrayLike, dut1: ArrayLike) -> tuple[Array, Array]:
    """Two-part UT1 Julian date of Unix (UTC) stamps, given UT1 - UTC `dut1` (s)."""
    u1, u2 = jd_utc(t_unix)
    return u1, u2 + np.asarray(dut1, dtype=float) / DAY_S


def tt_elapsed(t0_unix: ArrayLike, t1_unix: ArrayLike) -> Array:
    """Elapsed TT (s) between two UTC stamps: their difference plus any leap second between."""
    t0 = np.asarray(t0_unix, dtype=float)
    t1 = np.asarray(t1_unix, dtype=float)
    out: Array = (t1 - t0) + (tai_minus_utc(t1) - tai_minus_utc(t0))
    return out


def stamp_seconds(sec: int, nanosec: int) -> float:
    """Unix seconds of a stamp held as whole seconds and nanoseconds (a ROS 2 Time's fields).

    The one rounding every reader of stamps uses, so that stamps round-trip exactly.
    """
    return float(sec) + float(nanosec) * 1e-9
